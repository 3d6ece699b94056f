#pragma once
// Non-linear refinement of a relative pose on the Sampson error of normalised correspondences.
//
// OpenCV 4.6's USAC returns the model of its best local optimisation on a small inlier
// sample, not a fit to all inliers; this polishes it, as the final least-squares step of
// COLMAP's LO-RANSAC does.

#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/epipolar.h"  // SampsonSquaredError
#include "loopsfm/geometry/rigid3.h"

namespace loopsfm {

// E = [t]x R of cam2_from_cam1 = (R, t), so that x2^T E x1 = 0 for normalised x1, x2.
Eigen::Matrix3d EssentialFromPose(const Rigid3d& cam2_from_cam1);

// Levenberg-Marquardt on the Sampson errors under a Cauchy loss of scale loss_scale
// (normalised units, e.g. the inlier threshold / focal length), over the rotation and the
// direction of the translation. Returns a pose with unit translation; returns `initial`
// unchanged when there are fewer than 5 correspondences or its translation is zero.
Rigid3d RefineRelativePose(const std::vector<Eigen::Vector2d>& points1,
                           const std::vector<Eigen::Vector2d>& points2, const Rigid3d& initial,
                           double loss_scale, int max_iterations = 30);

}  // namespace loopsfm
