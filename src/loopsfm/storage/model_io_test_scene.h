#pragma once
// A small reconstruction for the model reader / writer tests, and a comparison of two
// reconstructions as COLMAP model files see them (registered images only, 3D points
// matched in id order).

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/reconstruction.h"

namespace loopsfm::model_io_test {

// Two cameras (PINHOLE, OPENCV), six images (image 6 unregistered), 3D points seen by 2-4
// registered images, extra 2D points without a 3D point, colours and errors set. One 3D
// point is deleted so the ids have a gap; one is also observed by the unregistered image.
inline Reconstruction MakeScene(int num_points = 40) {
  Random random(42);
  Reconstruction rec;
  Camera pinhole;
  pinhole.camera_id = 1;
  pinhole.model_id = CameraModelId::kPinhole;
  pinhole.width = 640;
  pinhole.height = 480;
  pinhole.params = {501.25, 499.5, 320.1, 239.7};
  rec.AddCamera(pinhole);
  Camera opencv;
  opencv.camera_id = 7;
  opencv.model_id = CameraModelId::kOpenCV;
  opencv.width = 1080;
  opencv.height = 1920;
  opencv.params = {1375.52, 1374.49, 554.558, 965.268, 0.0578, -0.0805, -0.00098, 0.000155};
  rec.AddCamera(opencv);

  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < num_points; ++i) {
    points.emplace_back(random.UniformReal(-2, 2), random.UniformReal(-2, 2),
                        random.UniformReal(6, 9));
  }
  for (image_t id = 1; id <= 6; ++id) {
    Image image;
    image.image_id = id;
    image.camera_id = id % 2 == 0 ? 7 : 1;
    image.name = "frame_" + std::to_string(1000 + id) + (id == 3 ? ".jpg" : ".png");
    image.cam_from_world = Rigid3d(
        Eigen::Quaterniond(Eigen::AngleAxisd(0.03 * id, Eigen::Vector3d(0.2, 1, 0.1).normalized())),
        Eigen::Vector3d(-0.4 * id + 1.0 / 3.0, 0.05 * id, 0.01 * id * id));
    const Camera& camera = rec.GetCamera(image.camera_id);
    for (const auto& p : points) {
      Point2D point2D;
      point2D.xy = camera.ImgFromCam(image.cam_from_world * p);
      image.points2D.push_back(point2D);
    }
    // Two 2D points that observe nothing.
    image.points2D.push_back({Eigen::Vector2d(10.5, 20.25)});
    image.points2D.push_back({Eigen::Vector2d(M_PI, M_E)});
    rec.AddImage(image);
    if (id != 6) rec.RegisterImage(id);
  }
  for (int i = 0; i < num_points; ++i) {
    Track track;
    const int length = 2 + i % 3;
    for (int k = 0; k < length; ++k) {
      track.elements.push_back({static_cast<image_t>(1 + (i + k) % 5), static_cast<point2D_t>(i)});
    }
    if (i == 1) track.elements.push_back({6, static_cast<point2D_t>(i)});
    const Eigen::Matrix<uint8_t, 3, 1> color(static_cast<uint8_t>(i * 5),
                                             static_cast<uint8_t>(255 - i),
                                             static_cast<uint8_t>(i % 7 * 30));
    const point3D_t id = rec.AddPoint3D(points[i], track, color);
    rec.GetPoint3D(id).error = 0.1 + 0.01 * i;
  }
  rec.DeletePoint3D(5);
  return rec;
}

inline std::vector<point3D_t> SortedIds(const Reconstruction& rec) {
  std::vector<point3D_t> ids;
  for (const auto& [id, p] : rec.Points3D()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

// Expects `read` to hold what a COLMAP model of `original` holds, with positions and
// parameters equal within `tolerance` (0 for an exact round trip).
inline void ExpectSameModel(const Reconstruction& original, const Reconstruction& read,
                            double tolerance) {
  ASSERT_EQ(read.Cameras().size(), original.Cameras().size());
  for (const auto& [id, camera] : original.Cameras()) {
    ASSERT_TRUE(read.ExistsCamera(id)) << id;
    const Camera& c = read.GetCamera(id);
    EXPECT_EQ(c.model_id, camera.model_id);
    EXPECT_EQ(c.width, camera.width);
    EXPECT_EQ(c.height, camera.height);
    ASSERT_EQ(c.params.size(), camera.params.size());
    for (size_t k = 0; k < c.params.size(); ++k) {
      EXPECT_NEAR(c.params[k], camera.params[k], tolerance * std::abs(camera.params[k]));
    }
  }
  // 3D point ids of `original` in the order they are written, mapped to `read`'s ids.
  const std::vector<point3D_t> original_ids = SortedIds(original), read_ids = SortedIds(read);
  ASSERT_EQ(read_ids.size(), original_ids.size());
  std::map<point3D_t, point3D_t> read_id_of;
  for (size_t i = 0; i < original_ids.size(); ++i) read_id_of[original_ids[i]] = read_ids[i];

  ASSERT_EQ(read.NumImages(), original.NumRegImages());
  EXPECT_EQ(read.NumRegImages(), original.NumRegImages());
  for (image_t id : original.RegImageIds()) {
    ASSERT_TRUE(read.ExistsImage(id)) << id;
    const Image& a = original.GetImage(id);
    const Image& b = read.GetImage(id);
    EXPECT_TRUE(b.registered);
    EXPECT_EQ(b.name, a.name);
    EXPECT_EQ(b.camera_id, a.camera_id);
    EXPECT_LE(b.cam_from_world.rotation.angularDistance(a.cam_from_world.rotation),
              tolerance + 1e-15);
    EXPECT_LE((b.cam_from_world.translation - a.cam_from_world.translation).norm(),
              tolerance + 1e-15);
    ASSERT_EQ(b.points2D.size(), a.points2D.size());
    for (size_t k = 0; k < a.points2D.size(); ++k) {
      EXPECT_LE((b.points2D[k].xy - a.points2D[k].xy).norm(), tolerance * 1e3) << id << " " << k;
      if (a.points2D[k].HasPoint3D()) {
        EXPECT_EQ(b.points2D[k].point3D_id, read_id_of.at(a.points2D[k].point3D_id));
      } else {
        EXPECT_FALSE(b.points2D[k].HasPoint3D());
      }
    }
    EXPECT_EQ(b.num_points3D, a.num_points3D);
  }
  for (size_t i = 0; i < original_ids.size(); ++i) {
    const Point3D& a = original.GetPoint3D(original_ids[i]);
    const Point3D& b = read.GetPoint3D(read_ids[i]);
    EXPECT_LE((b.xyz - a.xyz).norm(), tolerance * 10 + 0.0);
    EXPECT_EQ(b.color, a.color);
    EXPECT_NEAR(b.error, a.error, tolerance + 0.0);
    std::vector<TrackElement> expected;
    for (const TrackElement& el : a.track.elements) {
      if (original.IsRegistered(el.image_id)) expected.push_back(el);
    }
    std::vector<TrackElement> got = b.track.elements;
    std::sort(expected.begin(), expected.end());
    std::sort(got.begin(), got.end());
    EXPECT_EQ(got, expected) << "point " << original_ids[i];
  }
}

}  // namespace loopsfm::model_io_test
