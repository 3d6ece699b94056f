#include "loopsfm/estimators/absolute_pose.h"

#include <algorithm>
#include <cmath>

#include <ceres/ceres.h>
#include <ceres/manifold.h>

#include "loopsfm/estimators/reprojection.h"
#include "loopsfm/robust/absolute_pose_estimator.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Reprojection error in pixels of one fixed 3D point under a variable pose and camera.
// Blocks: rotation (4, Eigen x y z w), translation (3), camera params (kNumParams).
template <typename CameraModel>
class PoseReprojectionCost {
 public:
  PoseReprojectionCost(const Eigen::Vector2d& observed, const Eigen::Vector3d& point3D_in_world)
      : observed_(observed), point3D_(point3D_in_world) {}

  static ceres::CostFunction* Create(const Eigen::Vector2d& observed,
                                     const Eigen::Vector3d& point3D_in_world) {
    return new ceres::AutoDiffCostFunction<PoseReprojectionCost, 2, 4, 3,
                                           CameraModel::kNumParams>(
        new PoseReprojectionCost(observed, point3D_in_world));
  }

  template <typename T>
  bool operator()(const T* rotation, const T* translation, const T* params,
                  T* residuals) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(rotation);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(translation);
    const Eigen::Matrix<T, 3, 1> p = q * point3D_.cast<T>() + t;
    CameraModel::ImgFromCam(params, p[0], p[1], p[2], &residuals[0], &residuals[1]);
    residuals[0] -= T(observed_.x());
    residuals[1] -= T(observed_.y());
    return true;
  }

 private:
  Eigen::Vector2d observed_;
  Eigen::Vector3d point3D_;
};

ceres::LossFunction* MakeLoss(RobustLossType type, double scale_px) {
  switch (type) {
    case RobustLossType::kTrivial: return nullptr;
    case RobustLossType::kSoftL1: return new ceres::SoftLOneLoss(scale_px);
    case RobustLossType::kCauchy: return new ceres::CauchyLoss(scale_px);
  }
  return nullptr;
}

double RmseReprojectionError(std::span<const uint32_t> indices,
                             std::span<const Eigen::Vector2d> points2D,
                             std::span<const Eigen::Vector3d> points3D,
                             const Rigid3d& cam_from_world, const Camera& camera) {
  double sum = 0.0;
  for (const uint32_t i : indices) {
    const Eigen::Vector3d p = cam_from_world * points3D[i];
    sum += (camera.ImgFromCam(p) - points2D[i]).squaredNorm();
  }
  return indices.empty() ? 0.0 : std::sqrt(sum / indices.size());
}

}  // namespace

void AbsolutePoseRefinementOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(loss_scale_px > 0, "pose refinement: loss_scale_px must be positive, got {}",
                         loss_scale_px);
  LOOPSFM_REQUIRE_OPTION(max_num_iterations >= 1,
                         "pose refinement: max_num_iterations must be >= 1, got {}",
                         max_num_iterations);
  LOOPSFM_REQUIRE_OPTION(gradient_tolerance >= 0,
                         "pose refinement: gradient_tolerance must be >= 0, got {}",
                         gradient_tolerance);
}

void AbsolutePoseEstimationOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(max_error_px > 0 && std::isfinite(max_error_px),
                         "absolute pose: max_error_px must be positive, got {}", max_error_px);
  LOOPSFM_REQUIRE_OPTION(min_num_inliers >= 3, "absolute pose: min_num_inliers must be >= 3, got {}",
                         min_num_inliers);
  RansacOptions ransac_checked = ransac;
  ransac_checked.max_error = 1.0;  // set from max_error_px at run time
  ransac_checked.Check();
  refinement.Check();
}

AbsolutePoseRefinementReport RefineAbsolutePose(const AbsolutePoseRefinementOptions& options,
                                                std::span<const char> inlier_mask,
                                                std::span<const Eigen::Vector2d> points2D,
                                                std::span<const Eigen::Vector3d> points3D_in_world,
                                                Rigid3d* cam_from_world, Camera* camera) {
  options.Check();
  LOOPSFM_CHECK_EQ(points2D.size(), points3D_in_world.size());
  LOOPSFM_CHECK(inlier_mask.empty() || inlier_mask.size() == points2D.size());
  LOOPSFM_CHECK(cam_from_world != nullptr && camera != nullptr);
  AbsolutePoseRefinementReport report;

  std::vector<uint32_t> used;
  for (uint32_t i = 0; i < points2D.size(); ++i) {
    if (inlier_mask.empty() || inlier_mask[i]) used.push_back(i);
  }
  const bool refine_intrinsics = options.refine_focal_length || options.refine_extra_params;
  if (used.size() < (refine_intrinsics ? 6u : 3u)) return report;
  report.num_residuals = static_cast<int>(used.size());
  report.initial_rmse_px =
      RmseReprojectionError(used, points2D, points3D_in_world, *cam_from_world, *camera);

  // Parameter blocks: copies, written back only on success.
  Eigen::Quaterniond rotation = cam_from_world->rotation.normalized();
  Eigen::Vector3d translation = cam_from_world->translation;
  std::vector<double> params = camera->params;

  ceres::Problem problem;
  ceres::LossFunction* loss = MakeLoss(options.loss_type, options.loss_scale_px);
  VisitCameraModel(camera->model_id, [&](auto model) {
    using Model = decltype(model);
    LOOPSFM_CHECK_EQ(params.size(), static_cast<size_t>(Model::kNumParams));
    for (const uint32_t i : used) {
      problem.AddResidualBlock(
          PoseReprojectionCost<Model>::Create(points2D[i], points3D_in_world[i]), loss,
          rotation.coeffs().data(), translation.data(), params.data());
    }
    // Camera parameters: constant, or only focal / extra ones free.
    std::vector<int> constant;
    for (int k = 0; k < Model::kNumParams; ++k) {
      const bool is_focal = k < Model::kNumFocal;
      const bool is_extra = k >= Model::kNumFocalAndPP;
      const bool free = (is_focal && options.refine_focal_length) ||
                        (is_extra && options.refine_extra_params);
      if (!free) constant.push_back(k);
    }
    if (static_cast<int>(constant.size()) == Model::kNumParams) {
      problem.SetParameterBlockConstant(params.data());
    } else {
      problem.SetManifold(params.data(), new ceres::SubsetManifold(Model::kNumParams, constant));
    }
  });
  problem.SetManifold(rotation.coeffs().data(), new ceres::EigenQuaternionManifold);

  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = options.max_num_iterations;
  solver_options.gradient_tolerance = options.gradient_tolerance;
  solver_options.num_threads = 1;
  solver_options.logging_type = ceres::SILENT;
  solver_options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  report.num_iterations = static_cast<int>(summary.iterations.size());

  const bool finite = rotation.coeffs().allFinite() && translation.allFinite() &&
                      std::all_of(params.begin(), params.end(),
                                  [](double v) { return std::isfinite(v); });
  if (!summary.IsSolutionUsable() || !finite) return report;
  Camera refined_camera = *camera;
  refined_camera.params = params;
  if (!(refined_camera.MeanFocalLength() > 0.0)) return report;

  cam_from_world->rotation = rotation.normalized();
  cam_from_world->translation = translation;
  *camera = refined_camera;
  report.final_rmse_px =
      RmseReprojectionError(used, points2D, points3D_in_world, *cam_from_world, *camera);
  report.success = true;
  return report;
}

AbsolutePoseReport EstimateAbsolutePose(std::span<const Eigen::Vector2d> points2D,
                                        std::span<const Eigen::Vector3d> points3D_in_world,
                                        const Camera& camera,
                                        const AbsolutePoseEstimationOptions& options,
                                        Random& random) {
  options.Check();
  LOOPSFM_CHECK_EQ(points2D.size(), points3D_in_world.size());
  AbsolutePoseReport report;

  std::vector<Eigen::Vector2d> points2D_normalized(points2D.size());
  for (size_t i = 0; i < points2D.size(); ++i) {
    points2D_normalized[i] = camera.CamFromImg(points2D[i]);
  }
  RansacOptions ransac_options = options.ransac;
  ransac_options.max_error = camera.CamFromImgThreshold(options.max_error_px);
  const RansacReport<Rigid3d> ransac =
      EstimateAbsolutePoseNormalized(points2D_normalized, points3D_in_world, ransac_options, random);
  report.num_trials = ransac.num_trials;
  if (!ransac.success) return report;
  report.cam_from_world = ransac.model;

  if (options.refine_pose) {
    AbsolutePoseRefinementOptions refinement = options.refinement;
    refinement.refine_focal_length = false;
    refinement.refine_extra_params = false;
    Camera camera_copy = camera;
    report.refinement_failed =
        !RefineAbsolutePose(refinement, ransac.inlier_mask, points2D, points3D_in_world,
                            &report.cam_from_world, &camera_copy)
             .success;
  }

  // Inliers by the pixel error of the final pose.
  const double squared_max_error = options.max_error_px * options.max_error_px;
  report.inlier_mask.assign(points2D.size(), 0);
  for (size_t i = 0; i < points2D.size(); ++i) {
    if (CalculateSquaredReprojectionError(points2D[i], points3D_in_world[i], report.cam_from_world,
                                          camera) <= squared_max_error) {
      report.inlier_mask[i] = 1;
      ++report.num_inliers;
    }
  }
  report.success = report.num_inliers >= options.min_num_inliers;
  return report;
}

}  // namespace loopsfm
