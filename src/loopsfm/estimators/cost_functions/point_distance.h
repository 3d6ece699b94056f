#pragma once
// Constraints between two 3D points, for loop closing: when a track is split where the
// trajectory drifted, its parts are tied back together by these terms.
//
// Parameter blocks: point3D_a_in_world (3), point3D_b_in_world (3).

#include <Eigen/Core>
#include <ceres/autodiff_cost_function.h>
#include <ceres/cost_function.h>

namespace loopsfm {

// weight * (|X_a - X_b| - distance): one residual. Not differentiable where X_a = X_b, so
// use PointCoincidenceCost for a target distance of zero.
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

// weight * (X_a - X_b): three residuals, pulling two points onto each other.
class PointCoincidenceCost {
 public:
  explicit PointCoincidenceCost(double weight) : weight_(weight) {}

  static ceres::CostFunction* Create(double weight = 1.0) {
    return new ceres::AutoDiffCostFunction<PointCoincidenceCost, 3, 3, 3>(
        new PointCoincidenceCost(weight));
  }

  template <typename T>
  bool operator()(const T* point_a, const T* point_b, T* residuals) const {
    for (int i = 0; i < 3; ++i) residuals[i] = T(weight_) * (point_a[i] - point_b[i]);
    return true;
  }

 private:
  double weight_;
};

}  // namespace loopsfm
