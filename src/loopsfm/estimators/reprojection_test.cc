#include "loopsfm/estimators/reprojection.h"

#include <gtest/gtest.h>

#include <limits>

namespace loopsfm {
namespace {

Camera RadialCamera() {
  Camera camera;
  camera.model_id = CameraModelId::kSimpleRadial;
  camera.width = 640;
  camera.height = 480;
  camera.params = {500, 320, 240, -0.08};
  return camera;
}

TEST(Reprojection, PixelErrorMatchesTheCameraModel) {
  const Camera camera = RadialCamera();
  const Rigid3d cam_from_world(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d(0, 1, 1).normalized())),
      Eigen::Vector3d(0.5, -0.2, 1.0));
  const Eigen::Vector3d point_in_cam(0.3, -0.2, 2.0);
  const Eigen::Vector3d point = cam_from_world.Inverse() * point_in_cam;
  const Eigen::Vector2d pixel = camera.ImgFromCam(point_in_cam);
  EXPECT_LT(CalculateSquaredReprojectionError(pixel, point, cam_from_world, camera), 1e-20);
  EXPECT_NEAR(CalculateSquaredReprojectionError(pixel + Eigen::Vector2d(3, 4), point,
                                                cam_from_world, camera),
              25.0, 1e-9);
  EXPECT_LT(CalculateAngularReprojectionError(pixel, point, cam_from_world, camera), 1e-10);
  const Eigen::Vector3d behind = cam_from_world.Inverse() * Eigen::Vector3d(0.3, -0.2, -2.0);
  EXPECT_EQ(CalculateSquaredReprojectionError(pixel, behind, cam_from_world, camera),
            std::numeric_limits<double>::max());
}

TEST(Reprojection, AngularThresholdFromPixels) {
  const Camera camera = RadialCamera();
  EXPECT_NEAR(AngularThresholdFromPixels(5.0, camera), std::atan(0.01), 1e-15);
  // Near the image centre, a pixel offset subtends about that angle.
  const Rigid3d identity;
  const Eigen::Vector3d on_axis(0, 0, 10);
  EXPECT_NEAR(CalculateAngularReprojectionError(Eigen::Vector2d(325, 240), on_axis, identity,
                                                camera),
              AngularThresholdFromPixels(5.0, camera), 1e-6);
}

}  // namespace
}  // namespace loopsfm
