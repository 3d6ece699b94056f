#pragma once
// Reprojection errors in pixels, for any camera model. The camera-free versions on
// normalised coordinates are in geometry/pose_checks.h; Ceres cost functions are in
// estimators/cost_functions/.

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/camera.h"

namespace loopsfm {

// Squared distance in pixels between an observed pixel and the projection of a point;
// std::numeric_limits<double>::max() when the point is not in front of the camera.
double CalculateSquaredReprojectionError(const Eigen::Vector2d& point2D,
                                         const Eigen::Vector3d& point3D_in_world,
                                         const Rigid3d& cam_from_world, const Camera& camera);

// Angle in radians between the ray of an observed pixel (undistorted by the camera) and
// the ray to the point, in [0, pi].
double CalculateAngularReprojectionError(const Eigen::Vector2d& point2D,
                                         const Eigen::Vector3d& point3D_in_world,
                                         const Rigid3d& cam_from_world, const Camera& camera);

// Angle in radians that a pixel error subtends at the image centre: atan(pixels / focal).
// Converts pixel thresholds for the angular filters of geometry/triangulation.h.
double AngularThresholdFromPixels(double pixels, const Camera& camera);

}  // namespace loopsfm
