#include "loopsfm/pipeline/undistort.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

Camera MakeCamera(CameraModelId model, std::vector<double> params, int width = 640,
                  int height = 480) {
  Camera camera;
  camera.camera_id = 4;
  camera.model_id = model;
  camera.width = width;
  camera.height = height;
  camera.params = std::move(params);
  camera.Check();
  return camera;
}

std::vector<Camera> DistortedCameras() {
  return {
      MakeCamera(CameraModelId::kSimpleRadial, {520, 321, 239, -0.15}),
      MakeCamera(CameraModelId::kRadial, {520, 318.5, 241, 0.08, -0.02}),
      MakeCamera(CameraModelId::kOpenCV, {530, 515, 322, 236, -0.2, 0.05, 0.001, -0.0007}),
      MakeCamera(CameraModelId::kFullOpenCV,
                 {530, 515, 322, 236, -0.2, 0.05, 0.001, -0.0007, 0.01, 0.02, -0.01, 0.005}),
      MakeCamera(CameraModelId::kOpenCVFisheye, {300, 300, 320, 240, 0.02, -0.01, 0.003, -0.001}),
      MakeCamera(CameraModelId::kSimpleRadialFisheye, {300, 321, 241, 0.03}),
      MakeCamera(CameraModelId::kPinhole, {500, 505, 319.5, 240.5}),
  };
}

// OpenCV's maps against loopsfm's own camera model: the source of every undistorted pixel
// is where the distorted camera projects that pixel's ray (COLMAP pixel convention, so the
// half-pixel shift between the two conventions is checked too).
TEST(Undistort, OpenCvMapsAgreeWithTheCameraModel) {
  for (const Camera& distorted : DistortedCameras()) {
    const ImageUndistorter undistorter(distorted);
    const Camera& pinhole = undistorter.undistorted();
    ASSERT_EQ(pinhole.model_id, CameraModelId::kPinhole);
    ASSERT_EQ(undistorter.map_x().rows, pinhole.height);
    ASSERT_EQ(undistorter.map_x().cols, pinhole.width);
    double worst = 0.0;
    for (int row = 0; row < pinhole.height; row += 7) {
      for (int col = 0; col < pinhole.width; col += 7) {
        const Eigen::Vector2d ray = pinhole.CamFromImg({col + 0.5, row + 0.5});
        const Eigen::Vector2d expected = distorted.ImgFromCam(ray.homogeneous());
        const Eigen::Vector2d mapped(undistorter.map_x().at<float>(row, col) + 0.5,
                                     undistorter.map_y().at<float>(row, col) + 0.5);
        worst = std::max(worst, (mapped - expected).norm());
      }
    }
    EXPECT_LT(worst, 2e-3) << distorted.ModelName();  // float maps: ~1e-4 px
  }
}

TEST(Undistort, EveryUndistortedPixelComesFromTheImage) {
  for (const Camera& distorted : DistortedCameras()) {
    const ImageUndistorter undistorter(distorted);
    const cv::Mat white(distorted.height, distorted.width, CV_8UC3, cv::Scalar(255, 255, 255));
    const cv::Mat out = undistorter.Undistort(white);
    cv::Mat grey;
    cv::cvtColor(out, grey, cv::COLOR_BGR2GRAY);
    EXPECT_EQ(cv::countNonZero(grey < 250), 0) << distorted.ModelName();
    // And the rectangle is not needlessly small: at least 70 % of the original area.
    EXPECT_GT(out.total(), 0.7 * white.total()) << distorted.ModelName();
  }
}

TEST(Undistort, PinholeCamerasStayAsTheyAre) {
  const Camera pinhole = MakeCamera(CameraModelId::kPinhole, {500, 505, 319.5, 240.5});
  const Camera same = UndistortedCamera(pinhole);
  EXPECT_EQ(same.width, pinhole.width);
  EXPECT_EQ(same.height, pinhole.height);
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(same.params[k], pinhole.params[k], 1e-9);
}

TEST(Undistort, UndistortedKeypointsAreWhereThePinholeCameraSeesThePoints) {
  const Camera distorted =
      MakeCamera(CameraModelId::kOpenCV, {530, 515, 322, 236, -0.2, 0.05, 0.001, -0.0007});
  Reconstruction model;
  model.AddCamera(distorted);
  Random random(7);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 50; ++i) {
    points.emplace_back(random.UniformReal(-2, 2), random.UniformReal(-1.5, 1.5),
                        random.UniformReal(4, 8));
  }
  for (image_t id = 1; id <= 3; ++id) {
    Image image;
    image.image_id = id;
    image.camera_id = distorted.camera_id;
    image.name = "f" + std::to_string(id) + ".png";
    image.cam_from_world = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * id, Eigen::Vector3d::UnitY())),
                                   Eigen::Vector3d(-0.3 * id, 0.0, 0.0));
    for (const Eigen::Vector3d& p : points) {
      Point2D point;
      point.xy = distorted.ImgFromCam(image.cam_from_world * p);
      image.points2D.push_back(point);
    }
    model.AddImage(image);
    model.RegisterImage(id);
  }
  for (size_t i = 0; i < points.size(); ++i) {
    Track track;
    for (image_t id = 1; id <= 3; ++id) track.elements.push_back({id, static_cast<point2D_t>(i)});
    model.AddPoint3D(points[i], track);
  }
  const Camera pinhole = UndistortedCamera(distorted);
  Reconstruction undistorted = UndistortReconstruction(model, {{distorted.camera_id, pinhole}});
  EXPECT_EQ(undistorted.GetCamera(distorted.camera_id).model_id, CameraModelId::kPinhole);
  // Exact keypoints stay exact: the moved keypoints are where the pinhole camera sees the
  // points (undistortion converges to 1e-14 on the normalised plane).
  EXPECT_LT(model.UpdateReprojectionErrors(), 1e-6);
  EXPECT_LT(undistorted.UpdateReprojectionErrors(), 1e-6);
  // And they moved: the distorted and undistorted keypoints differ by pixels at the edges.
  double largest_move = 0.0;
  for (size_t i = 0; i < points.size(); ++i) {
    largest_move = std::max(largest_move, (model.GetImage(1).points2D[i].xy -
                                           undistorted.GetImage(1).points2D[i].xy).norm());
  }
  EXPECT_GT(largest_move, 5.0);
}

TEST(Undistort, AFrameOfAnotherSizeIsRefused) {
  const ImageUndistorter undistorter(
      MakeCamera(CameraModelId::kSimpleRadial, {520, 321, 239, -0.15}));
  EXPECT_THROW(undistorter.Undistort(cv::Mat(100, 100, CV_8UC3)), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
