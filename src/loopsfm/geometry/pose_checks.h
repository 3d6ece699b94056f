#pragma once
// Small checks on a pose and a point, camera-model free: depth and cheirality, errors of a
// projection in normalised image coordinates (z = 1 plane) and as an angle, and the
// difference between two poses. Pixel errors, which need a Camera, live in estimators/.

#include <limits>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"

namespace loopsfm {

// Depth of a point along the camera's optical axis (z in camera coordinates).
double CalculateDepth(const Eigen::Matrix<double, 3, 4>& cam_from_world,
                      const Eigen::Vector3d& point3D_in_world);

// Cheirality: true when the point lies in front of the camera (depth > 0, with a margin
// of machine precision relative to the point's distance).
bool HasPointPositiveDepth(const Eigen::Matrix<double, 3, 4>& cam_from_world,
                           const Eigen::Vector3d& point3D_in_world);
bool HasPointPositiveDepth(const Rigid3d& cam_from_world, const Eigen::Vector3d& point3D_in_world);

// Squared distance between an observed normalised image point and the projection of a
// point; +infinity (std::numeric_limits<double>::max()) when the point is not in front.
double CalculateSquaredNormalizedReprojectionError(const Eigen::Vector2d& point2D_normalized,
                                                   const Eigen::Vector3d& point3D_in_world,
                                                   const Rigid3d& cam_from_world);

// Angle in radians between the ray of an observed normalised image point and the ray to
// the point, in [0, pi]. Defined for points behind the camera too (then it is large).
double CalculateAngularError(const Eigen::Vector2d& point2D_normalized,
                             const Eigen::Vector3d& point3D_in_world,
                             const Rigid3d& cam_from_world);

// Projection centre of a camera in world coordinates.
inline Eigen::Vector3d ProjectionCenter(const Rigid3d& cam_from_world) {
  return -(cam_from_world.rotation.inverse() * cam_from_world.translation);
}

// Angle in degrees of the rotation between two poses' orientations, in [0, 180].
double RotationErrorDegrees(const Rigid3d& cam_from_world1, const Rigid3d& cam_from_world2);

// Distance between the projection centres of two poses.
double CenterError(const Rigid3d& cam_from_world1, const Rigid3d& cam_from_world2);

// Two-view cheirality test for a relative pose (e.g. one of the four decompositions of an
// essential matrix). Triangulates every correspondence of normalised image points and
// keeps those in front of both cameras and closer than max_depth times the baseline
// (points further away carry no information about the translation's sign). Returns true
// when at least one point passes; the passing points (in camera-1 coordinates) are
// written to points3D_in_cam1 when it is not null.
bool CheckCheirality(const Rigid3d& cam2_from_cam1,
                     std::span<const Eigen::Vector2d> points1_normalized,
                     std::span<const Eigen::Vector2d> points2_normalized,
                     std::vector<Eigen::Vector3d>* points3D_in_cam1, double max_depth = 1000.0);

}  // namespace loopsfm
