#pragma once
// Reprojection error of a 3D point in one image, templated on the camera model for Ceres'
// automatic differentiation. Residuals are in pixels: projected - observed.
//
// Parameter blocks, in order:
//   cam_from_world rotation   4  Eigen quaternion coefficients (x, y, z, w); use
//                                ceres::EigenQuaternionManifold and keep it unit norm
//   cam_from_world translation 3
//   point3D_in_world          3
//   camera params             Model::kNumParams, in the model's order (see kParamsInfo)
// The constant-pose variant stores cam_from_world and has only the last two blocks.
//
// A point behind the camera still yields a finite residual (no cheirality test), as in
// COLMAP; the mapper removes such observations by their reprojection error.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ceres/autodiff_cost_function.h>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/sensor/camera_models.h"

namespace loopsfm {

template <typename CameraModel>
class ReprojectionErrorCost {
 public:
  explicit ReprojectionErrorCost(const Eigen::Vector2d& observed) : observed_(observed) {}

  static ceres::CostFunction* Create(const Eigen::Vector2d& observed) {
    return new ceres::AutoDiffCostFunction<ReprojectionErrorCost, 2, 4, 3, 3,
                                           CameraModel::kNumParams>(
        new ReprojectionErrorCost(observed));
  }

  template <typename T>
  bool operator()(const T* cam_from_world_rotation, const T* cam_from_world_translation,
                  const T* point3D_in_world, const T* camera_params, T* residuals) const {
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(cam_from_world_rotation);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(cam_from_world_translation);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> point(point3D_in_world);
    const Eigen::Matrix<T, 3, 1> point_in_cam = rotation * point + translation;
    CameraModel::ImgFromCam(camera_params, point_in_cam[0], point_in_cam[1], point_in_cam[2],
                            &residuals[0], &residuals[1]);
    residuals[0] -= T(observed_.x());
    residuals[1] -= T(observed_.y());
    return true;
  }

 private:
  Eigen::Vector2d observed_;
};

// The pose is data, not a parameter: for images whose pose is held constant (cheaper than a
// constant parameter block, whose Jacobian autodiff would still compute).
template <typename CameraModel>
class ReprojectionErrorConstantPoseCost {
 public:
  ReprojectionErrorConstantPoseCost(const Rigid3d& cam_from_world, const Eigen::Vector2d& observed)
      : rotation_(cam_from_world.rotation.normalized().toRotationMatrix()),
        translation_(cam_from_world.translation),
        observed_(observed) {}

  static ceres::CostFunction* Create(const Rigid3d& cam_from_world,
                                     const Eigen::Vector2d& observed) {
    return new ceres::AutoDiffCostFunction<ReprojectionErrorConstantPoseCost, 2, 3,
                                           CameraModel::kNumParams>(
        new ReprojectionErrorConstantPoseCost(cam_from_world, observed));
  }

  template <typename T>
  bool operator()(const T* point3D_in_world, const T* camera_params, T* residuals) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> point(point3D_in_world);
    const Eigen::Matrix<T, 3, 1> point_in_cam =
        rotation_.cast<T>() * point + translation_.cast<T>();
    CameraModel::ImgFromCam(camera_params, point_in_cam[0], point_in_cam[1], point_in_cam[2],
                            &residuals[0], &residuals[1]);
    residuals[0] -= T(observed_.x());
    residuals[1] -= T(observed_.y());
    return true;
  }

 private:
  Eigen::Matrix3d rotation_;
  Eigen::Vector3d translation_;
  Eigen::Vector2d observed_;
};

// Runtime dispatch on the camera model.
inline ceres::CostFunction* CreateReprojectionErrorCost(CameraModelId model_id,
                                                        const Eigen::Vector2d& observed) {
  return VisitCameraModel(model_id, [&](auto model) -> ceres::CostFunction* {
    return ReprojectionErrorCost<decltype(model)>::Create(observed);
  });
}

inline ceres::CostFunction* CreateReprojectionErrorConstantPoseCost(
    CameraModelId model_id, const Rigid3d& cam_from_world, const Eigen::Vector2d& observed) {
  return VisitCameraModel(model_id, [&](auto model) -> ceres::CostFunction* {
    return ReprojectionErrorConstantPoseCost<decltype(model)>::Create(cam_from_world, observed);
  });
}

}  // namespace loopsfm
