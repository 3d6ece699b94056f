#pragma once
// Pose-graph term: the relative pose b_from_a = cam_b_from_world * inverse(cam_a_from_world)
// of two images should equal a measured one.
//
// Parameter blocks: cam_a_from_world (7: Eigen quaternion x, y, z, w, then the translation;
// the bundle's pose block, see reprojection_error.h), cam_b_from_world (7).
// Residuals (6): sqrt_information * [rotation error; translation error], where the rotation
// error is the angle-axis vector (small-angle: 2 * vec) of inverse(measured) * estimated
// and the translation error is estimated - measured translation of b_from_a.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ceres/autodiff_cost_function.h>

#include "loopsfm/geometry/rigid3.h"

namespace loopsfm {

class RelativePoseCost {
 public:
  RelativePoseCost(const Rigid3d& measured_b_from_a,
                   const Eigen::Matrix<double, 6, 6>& sqrt_information)
      : measured_rotation_inverse_(measured_b_from_a.rotation.normalized().inverse()),
        measured_translation_(measured_b_from_a.translation),
        sqrt_information_(sqrt_information) {}

  static ceres::CostFunction* Create(const Rigid3d& measured_b_from_a,
                                     const Eigen::Matrix<double, 6, 6>& sqrt_information =
                                         Eigen::Matrix<double, 6, 6>::Identity()) {
    return new ceres::AutoDiffCostFunction<RelativePoseCost, 6, 7, 7>(
        new RelativePoseCost(measured_b_from_a, sqrt_information));
  }

  template <typename T>
  bool operator()(const T* cam_a_from_world, const T* cam_b_from_world, T* residuals) const {
    const Eigen::Map<const Eigen::Quaternion<T>> qa(cam_a_from_world);
    const Eigen::Map<const Eigen::Quaternion<T>> qb(cam_b_from_world);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> ta(cam_a_from_world + 4);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> tb(cam_b_from_world + 4);
    const Eigen::Quaternion<T> b_from_a_rotation = qb * qa.conjugate();
    const Eigen::Matrix<T, 3, 1> b_from_a_translation = tb - b_from_a_rotation * ta;

    const Eigen::Quaternion<T> error_rotation =
        measured_rotation_inverse_.cast<T>() * b_from_a_rotation;
    // q and -q are the same rotation; take the one with w >= 0 so the error is small.
    const T sign = error_rotation.w() < T(0) ? T(-1) : T(1);
    Eigen::Matrix<T, 6, 1> error;
    error.template head<3>() = T(2) * sign * error_rotation.vec();
    error.template tail<3>() = b_from_a_translation - measured_translation_.cast<T>();

    Eigen::Map<Eigen::Matrix<T, 6, 1>> out(residuals);
    out = sqrt_information_.cast<T>() * error;
    return true;
  }

 private:
  Eigen::Quaterniond measured_rotation_inverse_;
  Eigen::Vector3d measured_translation_;
  Eigen::Matrix<double, 6, 6> sqrt_information_;
};

}  // namespace loopsfm
