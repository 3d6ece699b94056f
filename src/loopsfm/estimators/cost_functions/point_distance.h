#pragma once
// Constraints between two 3D points, for loop closing: when a track is split where the
// trajectory drifted, its parts are tied back together by these terms.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ceres/autodiff_cost_function.h>
#include <ceres/cost_function.h>

namespace loopsfm {

// weight * (|X_a - X_b| - distance): one residual. Not differentiable where X_a = X_b, so
// use DepthScaledCoincidenceCost for a target distance of zero.
class PointDistanceCost {
 public:
  PointDistanceCost(double distance, double weight) : distance_(distance), weight_(weight) {}

  static ceres::CostFunction* Create(double distance, double weight = 1.0) {
    return new ceres::AutoDiffCostFunction<PointDistanceCost, 1, 3, 3>(
        new PointDistanceCost(distance, weight));
  }

  template <typename T>
  bool operator()(const T* point_a, const T* point_b, T* residual) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> a(point_a);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> b(point_b);
    const T squared = (a - b).squaredNorm();
    // sqrt'(0) is infinite; the residual is then treated as flat (zero Jacobian).
    if (squared <= T(0)) {
      residual[0] = T(-weight_ * distance_) + T(0) * point_a[0];
      return true;
    }
    residual[0] = T(weight_) * (sqrt(squared) - T(distance_));
    return true;
  }

 private:
  double distance_;
  double weight_;
};

// weight * (X_a - X_b) / depth: three residuals pulling two points onto each other, their
// separation measured against the depth of their midpoint in an observing frame, so that
// weight = focal length gives about the separation in pixels as that frame sees it. Scale
// free: a similarity of the whole model (points and cameras) leaves the cost unchanged, so
// the term cannot be lowered by shrinking the model away from a fixed gauge, as a term in
// world units can (monocular scale is arbitrary). Not finite where the midpoint is not in
// front of the frame: a step that takes it there is rejected.
//
// Parameter blocks: point3D_a_in_world (3), point3D_b_in_world (3), and the observing frame's
// cam_from_world (7: Eigen quaternion x, y, z, w, unit norm, then the translation; the
// bundle's pose block, see reprojection_error.h).
class DepthScaledCoincidenceCost {
 public:
  explicit DepthScaledCoincidenceCost(double weight) : weight_(weight) {}

  static ceres::CostFunction* Create(double weight = 1.0) {
    return new ceres::AutoDiffCostFunction<DepthScaledCoincidenceCost, 3, 3, 3, 7>(
        new DepthScaledCoincidenceCost(weight));
  }

  template <typename T>
  bool operator()(const T* point_a, const T* point_b, const T* cam_from_world,
                  T* residuals) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> a(point_a);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> b(point_b);
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(cam_from_world);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(cam_from_world + 4);
    const Eigen::Matrix<T, 3, 1> midpoint = T(0.5) * (a + b);
    const T depth = (rotation * midpoint).z() + translation.z();
    if (!(depth > T(0))) return false;
    for (int i = 0; i < 3; ++i) residuals[i] = T(weight_) * (point_a[i] - point_b[i]) / depth;
    return true;
  }

 private:
  double weight_;
};

}  // namespace loopsfm
