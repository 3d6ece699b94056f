#include "loopsfm/estimators/reprojection.h"

#include <cmath>
#include <limits>

#include "loopsfm/geometry/pose_checks.h"

namespace loopsfm {

double CalculateSquaredReprojectionError(const Eigen::Vector2d& point2D,
                                         const Eigen::Vector3d& point3D_in_world,
                                         const Rigid3d& cam_from_world, const Camera& camera) {
  const Eigen::Vector3d point_in_cam = cam_from_world * point3D_in_world;
  if (!(point_in_cam.z() > std::numeric_limits<double>::epsilon() * point_in_cam.norm())) {
    return std::numeric_limits<double>::max();
  }
  return (camera.ImgFromCam(point_in_cam) - point2D).squaredNorm();
}

double CalculateAngularReprojectionError(const Eigen::Vector2d& point2D,
                                         const Eigen::Vector3d& point3D_in_world,
                                         const Rigid3d& cam_from_world, const Camera& camera) {
  return CalculateAngularError(camera.CamFromImg(point2D), point3D_in_world, cam_from_world);
}

double AngularThresholdFromPixels(double pixels, const Camera& camera) {
  return std::atan(pixels / camera.MeanFocalLength());
}

}  // namespace loopsfm
