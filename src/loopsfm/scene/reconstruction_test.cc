#include "loopsfm/scene/reconstruction.h"

#include <gtest/gtest.h>

namespace loopsfm {
namespace {

// Two cameras 1 m apart looking down +z at points 5 m away, with exact observations.
Reconstruction TwoViewScene(int num_points) {
  Reconstruction rec;
  Camera camera;
  camera.camera_id = 1;
  camera.model_id = CameraModelId::kSimpleRadial;
  camera.width = 640;
  camera.height = 480;
  camera.params = {500, 320, 240, -0.05};
  rec.AddCamera(camera);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < num_points; ++i) points.emplace_back(0.1 * i - 0.5, 0.05 * i - 0.3, 5.0 + 0.1 * i);
  for (image_t id : {1u, 2u}) {
    Image image;
    image.image_id = id;
    image.camera_id = 1;
    image.name = "frame_" + std::to_string(id);
    image.cam_from_world = Rigid3d(
        Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * id, Eigen::Vector3d::UnitY())),
        Eigen::Vector3d(-1.0 * (id - 1), 0, 0));
    for (const auto& p : points) image.points2D.push_back({camera.ImgFromCam(image.cam_from_world * p)});
    rec.AddImage(image);
    rec.RegisterImage(id);
  }
  for (int i = 0; i < num_points; ++i) {
    Track track;
    track.elements = {{1, static_cast<point2D_t>(i)}, {2, static_cast<point2D_t>(i)}};
    rec.AddPoint3D(points[i], track);
  }
  return rec;
}

TEST(Reconstruction, ExactSceneHasZeroReprojectionError) {
  Reconstruction rec = TwoViewScene(10);
  EXPECT_NEAR(rec.UpdateReprojectionErrors(), 0.0, 1e-9);
  EXPECT_EQ(rec.NumPoints3D(), 10u);
  EXPECT_EQ(rec.GetImage(1).num_points3D, 10u);
  EXPECT_DOUBLE_EQ(rec.ComputeMeanTrackLength(), 2.0);
}

TEST(Reconstruction, SimilarityTransformKeepsReprojectionsAndMovesCentres) {
  Reconstruction rec = TwoViewScene(10);
  Sim3d sim;
  sim.scale = 2.5;
  sim.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()));
  sim.translation = Eigen::Vector3d(3, -1, 2);
  const Eigen::Vector3d centre2 = rec.GetImage(2).ProjectionCenter();
  rec.Transform(sim);
  EXPECT_NEAR(rec.UpdateReprojectionErrors(), 0.0, 1e-9);
  EXPECT_LT((rec.GetImage(2).ProjectionCenter() - sim * centre2).norm(), 1e-9);
}

TEST(Reconstruction, DeletingObservationsKeepsCountsConsistent) {
  Reconstruction rec = TwoViewScene(4);
  const point3D_t id = rec.GetImage(1).points2D[0].point3D_id;
  rec.DeleteObservation(1, 0);  // a 2-view point loses its point entirely
  EXPECT_FALSE(rec.ExistsPoint3D(id));
  EXPECT_FALSE(rec.GetImage(2).points2D[0].HasPoint3D());
  EXPECT_EQ(rec.GetImage(2).num_points3D, 3u);
  rec.DeRegisterImage(2);
  EXPECT_EQ(rec.NumPoints3D(), 0u);
  EXPECT_EQ(rec.NumRegImages(), 1u);
  EXPECT_EQ(rec.GetImage(1).num_points3D, 0u);
}

TEST(Reconstruction, MergeJoinsTracks) {
  Reconstruction rec = TwoViewScene(2);
  const point3D_t a = rec.GetImage(1).points2D[0].point3D_id;
  const point3D_t b = rec.GetImage(1).points2D[1].point3D_id;
  const point3D_t merged = rec.MergePoints3D(a, b);
  EXPECT_EQ(rec.NumPoints3D(), 1u);
  EXPECT_EQ(rec.GetPoint3D(merged).track.Length(), 4u);
  EXPECT_EQ(rec.GetImage(1).num_points3D, 2u);
}

}  // namespace
}  // namespace loopsfm
