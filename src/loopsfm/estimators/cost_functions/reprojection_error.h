#pragma once
// Reprojection error of a 3D point in one image, templated on the camera model for Ceres'
// automatic differentiation. Residuals are in pixels: projected - observed.
//
// Parameter blocks, in order:
//   cam_from_world            7  Eigen quaternion coefficients (x, y, z, w), then the
//                                translation (PoseParameters in rigid3.h); use a manifold
//                                that keeps the quaternion unit norm (BundleAdjuster uses
//                                PoseCentreManifold, pose_manifold.h)
//   point3D_in_world          3
//   camera params             Model::kNumParams, in the model's order (see kParamsInfo)
// One pose block, not a rotation and a translation: Ceres' Schur complement then has one
// 6x6 block per pair of co-observing images instead of four 3x3 ones, a quarter of the
// block look-ups and locks when the points are eliminated (SchurEliminator<2, 3, 6>).
// The constant-pose variant stores cam_from_world and has only the last two blocks; the
// constant-camera variants store the camera parameters and drop the last block. A constant
// block is cheaper as data than as a constant parameter block: automatic differentiation
// would still carry its derivatives (14 per residual instead of 10 for a posed image with a
// known camera, 7 instead of 3 for an anchoring observation). The two costs with a pose and a
// point, the ones bundles evaluate most, have analytic derivatives instead.
//
// A point behind the camera still yields a finite residual (no cheirality test), as in
// COLMAP; the mapper removes such observations by their reprojection error.

#include <algorithm>
#include <array>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ceres/autodiff_cost_function.h>
#include <ceres/jet.h>
#include <ceres/sized_cost_function.h>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/sensor/camera_models.h"

namespace loopsfm {

// Residual of a point in camera coordinates: projected - observed.
template <typename CameraModel, typename T>
void ProjectionResidual(const T* camera_params, const Eigen::Matrix<T, 3, 1>& point_in_cam,
                        const Eigen::Vector2d& observed, T* residuals) {
  CameraModel::ImgFromCam(camera_params, point_in_cam[0], point_in_cam[1], point_in_cam[2],
                          &residuals[0], &residuals[1]);
  residuals[0] -= T(observed.x());
  residuals[1] -= T(observed.y());
}

// Camera parameters held as data, cast to the evaluation's scalar type.
template <typename CameraModel>
class CameraParamsData {
 public:
  explicit CameraParamsData(const std::vector<double>& params) {
    std::copy(params.begin(), params.begin() + CameraModel::kNumParams, params_.begin());
  }
  template <typename T>
  std::array<T, CameraModel::kNumParams> As() const {
    std::array<T, CameraModel::kNumParams> cast;
    for (int i = 0; i < CameraModel::kNumParams; ++i) cast[i] = T(params_[i]);
    return cast;
  }

 private:
  std::array<double, CameraModel::kNumParams> params_;
};

// The definition of the reprojection error, for automatic differentiation: the reference
// that the analytic costs below are tested against (to rounding).
template <typename CameraModel>
class ReprojectionErrorAutoDiff {
 public:
  explicit ReprojectionErrorAutoDiff(const Eigen::Vector2d& observed) : observed_(observed) {}

  static ceres::CostFunction* Create(const Eigen::Vector2d& observed) {
    return new ceres::AutoDiffCostFunction<ReprojectionErrorAutoDiff, 2, 7, 3,
                                           CameraModel::kNumParams>(
        new ReprojectionErrorAutoDiff(observed));
  }

  template <typename T>
  bool operator()(const T* cam_from_world, const T* point3D_in_world, const T* camera_params,
                  T* residuals) const {
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(cam_from_world);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(cam_from_world + 4);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> point(point3D_in_world);
    ProjectionResidual<CameraModel, T>(camera_params, rotation * point + translation, observed_,
                                       residuals);
    return true;
  }

 private:
  Eigen::Vector2d observed_;
};

// A world point in a camera, p = R(q) X + t, with Eigen's quaternion rotation written out,
// X + 2 w (u x X) + 2 u x (u x X) with q = (u, w), and its derivatives by hand: the pose and
// point half of the analytic costs below. (Automatic differentiation would carry the
// derivatives of all ten pose and point parameters through the rotation.)
class PointInCameraWithDerivatives {
 public:
  // cam_from_world: the 7 pose parameters (quaternion x, y, z, w, then translation).
  PointInCameraWithDerivatives(const double* cam_from_world, const double* point)
      : u_(cam_from_world), w_(cam_from_world[3]), point_(point), u_cross_point_(u_.cross(point_)) {
    point_in_cam_ = point_ + 2.0 * (w_ * u_cross_point_ + u_.cross(u_cross_point_)) +
                    Eigen::Map<const Eigen::Vector3d>(cam_from_world + 4);
  }

  const Eigen::Vector3d& point_in_cam() const { return point_in_cam_; }

  // Chain rule: from d residual / d p (2x3) to the pose and point blocks (jacobians[0..1],
  // Ceres' row-major layout; a null entry is skipped).
  void Chain(const Eigen::Matrix<double, 2, 3, Eigen::RowMajor>& d_projected,
             double** jacobians) const {
    if (jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> d_pose(jacobians[0]);
      // d p / d u = 2 (-w [X]x + (u.X) I - 2 X u^T + u X^T);  d p / d w = 2 (u x X).
      Eigen::Matrix<double, 3, 4> d_rotation;
      d_rotation.leftCols<3>() =
          2.0 * (-w_ * CrossMatrix(point_) + u_.dot(point_) * Eigen::Matrix3d::Identity() -
                 2.0 * point_ * u_.transpose() + u_ * point_.transpose());
      d_rotation.col(3) = 2.0 * u_cross_point_;
      d_pose.leftCols<4>() = d_projected * d_rotation;
      d_pose.rightCols<3>() = d_projected;
    }
    if (jacobians[1] != nullptr) {
      // d p / d X = I + 2 w [u]x + 2 [u]x [u]x (the rotation matrix when |q| = 1).
      const Eigen::Matrix3d u_cross = CrossMatrix(u_);
      Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> d_x(jacobians[1]);
      d_x = d_projected *
          (Eigen::Matrix3d::Identity() + 2.0 * w_ * u_cross + 2.0 * u_cross * u_cross);
    }
  }

 private:
  static Eigen::Matrix3d CrossMatrix(const Eigen::Vector3d& v) {
    Eigen::Matrix3d m;
    m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
    return m;
  }

  Eigen::Map<const Eigen::Vector3d> u_;
  double w_;
  Eigen::Map<const Eigen::Vector3d> point_;
  Eigen::Vector3d u_cross_point_;
  Eigen::Vector3d point_in_cam_;
};

// The cost of an observation whose camera parameters are refined (global bundles without
// known intrinsics), with analytic derivatives: the projection's derivatives with respect to
// the point in the camera and the camera parameters come from the camera model through one
// Jet of 3 + kNumParams components (7 for SIMPLE_RADIAL, where automatic differentiation of
// the whole cost carries 14), the pose and point ones from PointInCameraWithDerivatives.
template <typename CameraModel>
class ReprojectionErrorCost
    : public ceres::SizedCostFunction<2, 7, 3, CameraModel::kNumParams> {
 public:
  explicit ReprojectionErrorCost(const Eigen::Vector2d& observed) : observed_(observed) {}

  static ceres::CostFunction* Create(const Eigen::Vector2d& observed) {
    return new ReprojectionErrorCost(observed);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const PointInCameraWithDerivatives posed(parameters[0], parameters[1]);
    const double* camera_params = parameters[2];
    if (jacobians == nullptr) {
      ProjectionResidual<CameraModel, double>(camera_params, posed.point_in_cam(), observed_,
                                              residuals);
      return true;
    }
    constexpr int kNumParams = CameraModel::kNumParams;
    using Jet = ceres::Jet<double, 3 + kNumParams>;
    const Eigen::Matrix<Jet, 3, 1> p(Jet(posed.point_in_cam()[0], 0),
                                     Jet(posed.point_in_cam()[1], 1),
                                     Jet(posed.point_in_cam()[2], 2));
    std::array<Jet, kNumParams> params;
    for (int i = 0; i < kNumParams; ++i) params[i] = Jet(camera_params[i], 3 + i);
    Jet projected[2];
    ProjectionResidual<CameraModel, Jet>(params.data(), p, observed_, projected);
    Eigen::Matrix<double, 2, 3, Eigen::RowMajor> d_projected;  // d residual / d point_in_cam
    for (int r = 0; r < 2; ++r) {
      residuals[r] = projected[r].a;
      d_projected.row(r) = projected[r].v.template head<3>().transpose();
      if (jacobians[2] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 1, kNumParams>> d_camera(jacobians[2] + r * kNumParams);
        d_camera = projected[r].v.template tail<kNumParams>().transpose();
      }
    }
    posed.Chain(d_projected, jacobians);
    return true;
  }

 private:
  Eigen::Vector2d observed_;
};

// The camera as data, with analytic derivatives: the cost of every observation in a bundle
// that holds its cameras fixed (all local bundles, and global ones with known intrinsics),
// so the one evaluated most. The projection's 2x3 derivative comes from the camera model
// through a 3-component Jet; the rest as in ReprojectionErrorCost. Same values as automatic
// differentiation of the same expression (to rounding), in about a third of the time: a
// 10-component Jet through the rotation is what it replaces.
template <typename CameraModel>
class ReprojectionErrorConstantCameraCost : public ceres::SizedCostFunction<2, 7, 3> {
 public:
  ReprojectionErrorConstantCameraCost(const std::vector<double>& camera_params,
                                      const Eigen::Vector2d& observed)
      : camera_(camera_params), observed_(observed) {}

  static ceres::CostFunction* Create(const std::vector<double>& camera_params,
                                     const Eigen::Vector2d& observed) {
    return new ReprojectionErrorConstantCameraCost(camera_params, observed);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const PointInCameraWithDerivatives posed(parameters[0], parameters[1]);
    if (jacobians == nullptr) {
      ProjectionResidual<CameraModel, double>(camera_.template As<double>().data(),
                                              posed.point_in_cam(), observed_, residuals);
      return true;
    }
    using Jet3 = ceres::Jet<double, 3>;
    const Eigen::Matrix<Jet3, 3, 1> p(Jet3(posed.point_in_cam()[0], 0),
                                      Jet3(posed.point_in_cam()[1], 1),
                                      Jet3(posed.point_in_cam()[2], 2));
    Jet3 projected[2];
    ProjectionResidual<CameraModel, Jet3>(camera_.template As<Jet3>().data(), p, observed_,
                                          projected);
    Eigen::Matrix<double, 2, 3, Eigen::RowMajor> d_projected;  // d residual / d point_in_cam
    for (int r = 0; r < 2; ++r) {
      residuals[r] = projected[r].a;
      d_projected.row(r) = projected[r].v.transpose();
    }
    posed.Chain(d_projected, jacobians);
    return true;
  }

 private:
  CameraParamsData<CameraModel> camera_;
  Eigen::Vector2d observed_;
};

// The pose is data, not a parameter: for images whose pose is held constant.
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
    ProjectionResidual<CameraModel, T>(camera_params, PointInCamera(point3D_in_world), observed_,
                                       residuals);
    return true;
  }

  template <typename T>
  Eigen::Matrix<T, 3, 1> PointInCamera(const T* point3D_in_world) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> point(point3D_in_world);
    return rotation_.cast<T>() * point + translation_.cast<T>();
  }

 private:
  Eigen::Matrix3d rotation_;
  Eigen::Vector3d translation_;
  Eigen::Vector2d observed_;
};

// Pose and camera both data: only the point is a parameter.
template <typename CameraModel>
class ReprojectionErrorConstantPoseCameraCost {
 public:
  ReprojectionErrorConstantPoseCameraCost(const Rigid3d& cam_from_world,
                                          const std::vector<double>& camera_params,
                                          const Eigen::Vector2d& observed)
      : pose_(cam_from_world, observed), camera_(camera_params), observed_(observed) {}

  static ceres::CostFunction* Create(const Rigid3d& cam_from_world,
                                     const std::vector<double>& camera_params,
                                     const Eigen::Vector2d& observed) {
    return new ceres::AutoDiffCostFunction<ReprojectionErrorConstantPoseCameraCost, 2, 3>(
        new ReprojectionErrorConstantPoseCameraCost(cam_from_world, camera_params, observed));
  }

  template <typename T>
  bool operator()(const T* point3D_in_world, T* residuals) const {
    ProjectionResidual<CameraModel, T>(camera_.template As<T>().data(),
                                       pose_.PointInCamera(point3D_in_world), observed_,
                                       residuals);
    return true;
  }

 private:
  ReprojectionErrorConstantPoseCost<CameraModel> pose_;
  CameraParamsData<CameraModel> camera_;
  Eigen::Vector2d observed_;
};

// Runtime dispatch on the camera model.
inline ceres::CostFunction* CreateReprojectionErrorCost(CameraModelId model_id,
                                                        const Eigen::Vector2d& observed) {
  return VisitCameraModel(model_id, [&](auto model) -> ceres::CostFunction* {
    return ReprojectionErrorCost<decltype(model)>::Create(observed);
  });
}

inline ceres::CostFunction* CreateReprojectionErrorAutoDiffCost(CameraModelId model_id,
                                                                const Eigen::Vector2d& observed) {
  return VisitCameraModel(model_id, [&](auto model) -> ceres::CostFunction* {
    return ReprojectionErrorAutoDiff<decltype(model)>::Create(observed);
  });
}

inline ceres::CostFunction* CreateReprojectionErrorConstantCameraCost(
    CameraModelId model_id, const std::vector<double>& camera_params,
    const Eigen::Vector2d& observed) {
  return VisitCameraModel(model_id, [&](auto model) -> ceres::CostFunction* {
    return ReprojectionErrorConstantCameraCost<decltype(model)>::Create(camera_params, observed);
  });
}

inline ceres::CostFunction* CreateReprojectionErrorConstantPoseCost(
    CameraModelId model_id, const Rigid3d& cam_from_world, const Eigen::Vector2d& observed) {
  return VisitCameraModel(model_id, [&](auto model) -> ceres::CostFunction* {
    return ReprojectionErrorConstantPoseCost<decltype(model)>::Create(cam_from_world, observed);
  });
}

inline ceres::CostFunction* CreateReprojectionErrorConstantPoseCameraCost(
    CameraModelId model_id, const Rigid3d& cam_from_world,
    const std::vector<double>& camera_params, const Eigen::Vector2d& observed) {
  return VisitCameraModel(model_id, [&](auto model) -> ceres::CostFunction* {
    return ReprojectionErrorConstantPoseCameraCost<decltype(model)>::Create(
        cam_from_world, camera_params, observed);
  });
}

}  // namespace loopsfm
