#pragma once
// Absolute pose of a calibrated camera from 2D-3D correspondences, robustly: P3P minimal
// samples in LO-RANSAC, residuals as squared reprojection errors in normalised image
// coordinates (the z = 1 plane), local optimisation by Levenberg-Marquardt on the inliers.
// Pixel-level wrappers (undistortion, thresholds in pixels, Ceres refinement with the
// camera model) are in estimators/absolute_pose.h.

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"
#include "loopsfm/robust/loransac.h"

namespace loopsfm {

// LO-RANSAC estimator (see loransac.h). Holds views of the data, which must outlive it.
class P3PEstimator {
 public:
  using Model = Rigid3d;  // cam_from_world
  static constexpr int kMinNumSamples = 3;

  P3PEstimator(std::span<const Eigen::Vector2d> points2D_normalized,
               std::span<const Eigen::Vector3d> points3D_in_world);

  size_t NumData() const { return points2D_.size(); }
  // Up to 4 poses from the three correspondences of the sample.
  std::vector<Rigid3d> Estimate(std::span<const uint32_t> sample) const;
  // Squared reprojection errors in normalised coordinates; max() for points not in front.
  void Residuals(const Rigid3d& cam_from_world, std::vector<double>* squared_residuals) const;
  // Refines the pose on the given correspondences (RefinePoseNormalized).
  bool EstimateNonMinimal(std::span<const uint32_t> inliers, Rigid3d* cam_from_world) const;

 private:
  std::span<const Eigen::Vector2d> points2D_;
  std::span<const Eigen::Vector3d> points3D_;
};

// Levenberg-Marquardt on the sum of squared reprojection errors in normalised coordinates
// of the correspondences listed in `indices` (at least 3), starting from *cam_from_world.
// A step is kept only if it lowers the cost and keeps every point in front of the camera.
// Returns false (pose unchanged) when the start is invalid or nothing could be computed.
bool RefinePoseNormalized(std::span<const Eigen::Vector2d> points2D_normalized,
                          std::span<const Eigen::Vector3d> points3D_in_world,
                          std::span<const uint32_t> indices, Rigid3d* cam_from_world,
                          int max_num_iterations = 10);

// P3P LO-RANSAC on normalised image points; options.max_error is in normalised units
// (a pixel threshold divided by the focal length).
RansacReport<Rigid3d> EstimateAbsolutePoseNormalized(
    std::span<const Eigen::Vector2d> points2D_normalized,
    std::span<const Eigen::Vector3d> points3D_in_world, const RansacOptions& options,
    Random& random);

}  // namespace loopsfm
