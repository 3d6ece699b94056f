#include "loopsfm/geometry/pose_checks.h"

#include <cmath>

#include "loopsfm/geometry/triangulation.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

double CalculateDepth(const Eigen::Matrix<double, 3, 4>& cam_from_world,
                      const Eigen::Vector3d& point3D_in_world) {
  return cam_from_world.row(2).head<3>().dot(point3D_in_world) + cam_from_world(2, 3);
}

bool HasPointPositiveDepth(const Eigen::Matrix<double, 3, 4>& cam_from_world,
                           const Eigen::Vector3d& point3D_in_world) {
  const Eigen::Vector3d point_in_cam =
      cam_from_world.leftCols<3>() * point3D_in_world + cam_from_world.col(3);
  return point_in_cam.z() > std::numeric_limits<double>::epsilon() * point_in_cam.norm();
}

bool HasPointPositiveDepth(const Rigid3d& cam_from_world, const Eigen::Vector3d& point3D_in_world) {
  const Eigen::Vector3d point_in_cam = cam_from_world * point3D_in_world;
  return point_in_cam.z() > std::numeric_limits<double>::epsilon() * point_in_cam.norm();
}

double CalculateSquaredNormalizedReprojectionError(const Eigen::Vector2d& point2D_normalized,
                                                   const Eigen::Vector3d& point3D_in_world,
                                                   const Rigid3d& cam_from_world) {
  const Eigen::Vector3d point_in_cam = cam_from_world * point3D_in_world;
  if (!(point_in_cam.z() > std::numeric_limits<double>::epsilon() * point_in_cam.norm())) {
    return std::numeric_limits<double>::max();
  }
  return (point_in_cam.head<2>() / point_in_cam.z() - point2D_normalized).squaredNorm();
}

double CalculateAngularError(const Eigen::Vector2d& point2D_normalized,
                             const Eigen::Vector3d& point3D_in_world,
                             const Rigid3d& cam_from_world) {
  const Eigen::Vector3d ray = point2D_normalized.homogeneous();
  const Eigen::Vector3d point_in_cam = cam_from_world * point3D_in_world;
  return std::atan2(ray.cross(point_in_cam).norm(), ray.dot(point_in_cam));
}

double RotationErrorDegrees(const Rigid3d& cam_from_world1, const Rigid3d& cam_from_world2) {
  return RotationAngleDegrees(cam_from_world1.rotation.inverse() * cam_from_world2.rotation);
}

double CenterError(const Rigid3d& cam_from_world1, const Rigid3d& cam_from_world2) {
  return (ProjectionCenter(cam_from_world1) - ProjectionCenter(cam_from_world2)).norm();
}

bool CheckCheirality(const Rigid3d& cam2_from_cam1,
                     std::span<const Eigen::Vector2d> points1_normalized,
                     std::span<const Eigen::Vector2d> points2_normalized,
                     std::vector<Eigen::Vector3d>* points3D_in_cam1, double max_depth) {
  LOOPSFM_CHECK_EQ(points1_normalized.size(), points2_normalized.size());
  const Matrix3x4d cam1_from_cam1 = Matrix3x4d::Identity();
  const Matrix3x4d cam2_from_cam1_matrix = cam2_from_cam1.ToMatrix();
  const double max_depth_abs = max_depth * cam2_from_cam1.translation.norm();
  if (points3D_in_cam1 != nullptr) points3D_in_cam1->clear();
  int num_in_front = 0;
  for (size_t i = 0; i < points1_normalized.size(); ++i) {
    const std::optional<Eigen::Vector3d> point = TriangulatePoint(
        cam1_from_cam1, cam2_from_cam1_matrix, points1_normalized[i], points2_normalized[i]);
    if (!point) continue;
    const double depth1 = point->z();
    const double depth2 = CalculateDepth(cam2_from_cam1_matrix, *point);
    const double eps = std::numeric_limits<double>::epsilon() * point->norm();
    if (depth1 > eps && depth2 > eps && depth1 < max_depth_abs && depth2 < max_depth_abs) {
      ++num_in_front;
      if (points3D_in_cam1 != nullptr) points3D_in_cam1->push_back(*point);
    }
  }
  return num_in_front > 0;
}

}  // namespace loopsfm
