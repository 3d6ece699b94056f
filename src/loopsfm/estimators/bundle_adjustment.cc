#include "loopsfm/estimators/bundle_adjustment.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <thread>
#include <tuple>

#include <ceres/autodiff_cost_function.h>
#include <ceres/manifold.h>

#include "loopsfm/estimators/bundle_settled.h"
#include "loopsfm/estimators/cost_functions/reprojection_error.h"
#include "loopsfm/estimators/pose_manifold.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

template <typename Set>
std::vector<typename Set::value_type> Sorted(const Set& set) {
  std::vector<typename Set::value_type> values(set.begin(), set.end());
  std::sort(values.begin(), values.end());
  return values;
}

ceres::LossFunction* CreateLossFunction(BundleLossFunction type, double scale) {
  switch (type) {
    case BundleLossFunction::kTrivial: return nullptr;
    case BundleLossFunction::kHuber: return new ceres::HuberLoss(scale);
    case BundleLossFunction::kSoftL1: return new ceres::SoftLOneLoss(scale);
    case BundleLossFunction::kCauchy: return new ceres::CauchyLoss(scale);
  }
  return nullptr;
}

// Indices of the camera parameters held fixed under the refine_* options.
std::vector<int> ConstantCameraParams(CameraModelId model_id,
                                      const BundleAdjustmentOptions& options) {
  return VisitCameraModel(model_id, [&](auto model) {
    using Model = decltype(model);
    std::vector<int> constant;
    for (int i = 0; i < Model::kNumParams; ++i) {
      const bool is_focal = i < Model::kNumFocal;
      const bool is_pp = !is_focal && i < Model::kNumFocalAndPP;
      const bool is_extra = i >= Model::kNumFocalAndPP;
      if ((is_focal && !options.refine_focal_length) ||
          (is_pp && !options.refine_principal_point) ||
          (is_extra && !options.refine_extra_params)) {
        constant.push_back(i);
      }
    }
    return constant;
  });
}

// Camera parameters with some held constant and, with tie_focal, fy tied to fx: a step d of
// the focal length moves fx by d and fy by d * fy / fx, so fy / fx never changes. The tangent
// space has one coordinate per free parameter (fx standing for both focal lengths).
class CameraParamsManifold : public ceres::Manifold {
 public:
  CameraParamsManifold(int num_params, const std::vector<int>& constant, bool tie_focal)
      : num_params_(num_params), tie_focal_(tie_focal) {
    for (int i = 0; i < num_params; ++i) {
      const bool is_constant = std::find(constant.begin(), constant.end(), i) != constant.end();
      if (!is_constant && !(tie_focal && i == 1)) free_.push_back(i);
    }
  }
  int AmbientSize() const override { return num_params_; }
  int TangentSize() const override { return static_cast<int>(free_.size()); }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    std::copy(x, x + num_params_, x_plus_delta);
    for (size_t k = 0; k < free_.size(); ++k) {
      x_plus_delta[free_[k]] += delta[k];
      if (tie_focal_ && free_[k] == 0) x_plus_delta[1] += delta[k] * x[1] / x[0];
    }
    return true;
  }
  bool PlusJacobian(const double* x, double* jacobian) const override {
    const int tangent = TangentSize();
    std::fill(jacobian, jacobian + num_params_ * tangent, 0.0);
    for (int k = 0; k < tangent; ++k) {
      jacobian[free_[k] * tangent + k] = 1.0;
      if (tie_focal_ && free_[k] == 0) jacobian[1 * tangent + k] = x[1] / x[0];
    }
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    for (size_t k = 0; k < free_.size(); ++k) y_minus_x[k] = y[free_[k]] - x[free_[k]];
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    const int tangent = TangentSize();
    std::fill(jacobian, jacobian + num_params_ * tangent, 0.0);
    for (int k = 0; k < tangent; ++k) jacobian[k * num_params_ + free_[k]] = 1.0;
    return true;
  }

 private:
  int num_params_;
  bool tie_focal_;
  std::vector<int> free_;
};

// Holds one coordinate of a pose's projection centre at its start value:
// r = weight * (c[k] - c0[k]) with c = -R^T t, on the 7-parameter pose block (quaternion
// coefficients x, y, z, w, then t). A prior rather than a manifold, so that the pose block
// keeps tangent size 6: with every pose block of one size, Ceres picks its fixed-size Schur
// kernel (SchurEliminator<2, 3, 6>; a SubsetManifold was measured 16 % slower on block.mp4's
// global bundle, bench/bundle_adjustment). The data cannot move the gauge, so at the optimum
// the prior is zero and the solution is the one the hard constraint gives.
struct CentreCoordinatePrior {
  template <typename T>
  bool operator()(const T* pose, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> rotation(pose);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> translation(pose + 4);
    const Eigen::Matrix<T, 3, 1> centre = -(rotation.conjugate() * translation);
    residual[0] = T(weight) * (centre[coord] - T(value));
    return true;
  }
  int coord;
  double value;
  double weight;
};

std::optional<ceres::SparseLinearAlgebraLibraryType> AvailableSparseLibrary() {
  for (const auto type : {ceres::SUITE_SPARSE, ceres::EIGEN_SPARSE, ceres::CX_SPARSE}) {
    if (ceres::IsSparseLinearAlgebraLibraryTypeAvailable(type)) return type;
  }
  return std::nullopt;
}

}  // namespace

BundleAdjuster::BundleAdjuster(const BundleAdjustmentOptions& options,
                               const BundleAdjustmentConfig& config)
    : options_(options), config_(config) {
  options_.Check();
}

BundleAdjuster::~BundleAdjuster() = default;

ceres::Problem& BundleAdjuster::problem() {
  LOOPSFM_CHECK_MSG(problem_ != nullptr, "BundleAdjuster::SetUp must be called first");
  return *problem_;
}

void BundleAdjuster::SetUp(Reconstruction* reconstruction) {
  LOOPSFM_CHECK_MSG(problem_ == nullptr, "BundleAdjuster::SetUp called twice");
  LOOPSFM_CHECK(reconstruction != nullptr);
  reconstruction_ = reconstruction;
  ceres::Problem::Options problem_options;
  // Parameter blocks are never removed, so the slow-removal index is not needed, and
  // cost functions, losses and manifolds are owned by the problem.
  problem_options.enable_fast_removal = false;
  problem_ = std::make_unique<ceres::Problem>(problem_options);
  loss_function_ = CreateLossFunction(options_.loss_function, options_.loss_function_scale);

  const std::vector<image_t> image_ids = Sorted(config_.ImageIds());
  std::vector<Eigen::Vector3d> centres;
  for (const image_t id : image_ids) {
    centres.push_back(reconstruction_->GetImage(id).ProjectionCenter());
  }
  const double spread = CentreSpread(centres);
  centre_spread_ = spread > 0.0 ? spread : 1.0;  // one image, or all at one place
  for (const image_t image_id : image_ids) AddImage(image_id);

  // The config's images' observations, grouped by point (in image order within a point).
  std::vector<Observation> observations;
  for (const image_t image_id : image_ids) {
    const Image& image = reconstruction_->GetImage(image_id);
    for (size_t idx = 0; idx < image.points2D.size(); ++idx) {
      const Point2D& point2D = image.points2D[idx];
      if (!point2D.HasPoint3D() || !config_.InPointSubset(point2D.point3D_id)) continue;
      observations.push_back({point2D.point3D_id, image_id, static_cast<uint32_t>(idx)});
    }
  }
  const auto by_point = [](const Observation& a, const Observation& b) {
    return a.point3D_id < b.point3D_id;
  };
  std::stable_sort(observations.begin(), observations.end(), by_point);
  // One entry per point: the number of variable poses it shares residuals with, its id, and
  // its observations' range.
  struct PointEntry {
    int num_variable_poses;
    point3D_t point3D_id;
    size_t begin, end;
  };
  std::vector<PointEntry> points;
  for (size_t begin = 0; begin < observations.size();) {
    size_t end = begin;
    int num_variable_poses = 0;
    for (; end < observations.size() &&
           observations[end].point3D_id == observations[begin].point3D_id;
         ++end) {
      if (!config_.HasConstantPose(observations[end].image_id)) ++num_variable_poses;
    }
    points.push_back({num_variable_poses, observations[begin].point3D_id, begin, end});
    begin = end;
  }
  // Points seen by the config's images, and those the config adds explicitly, enter with
  // their observations by the other registered images (poses constant there).
  std::unordered_set<point3D_t> variable_points;
  for (const PointEntry& entry : points) {
    if (!config_.HasConstantPoint(entry.point3D_id)) variable_points.insert(entry.point3D_id);
  }
  for (const point3D_t id : config_.VariablePoints()) {
    if (!reconstruction_->ExistsPoint3D(id) || variable_points.count(id) > 0) continue;
    const bool seen = std::binary_search(observations.begin(), observations.end(),
                                         Observation{id, 0, 0}, by_point);
    if (!seen) points.push_back({0, id, 0, 0});
    variable_points.insert(id);
  }

  // The residuals go in point by point, in the order Ceres' Schur solvers eliminate the
  // points: by the number of variable poses a point shares residuals with, then in the
  // order added. Ceres evaluates the residuals in that order on every iteration, so their
  // cost functions lie in memory in the order they are read; added image by image, each
  // evaluation fetched them from all over the heap (a quarter of a local bundle's time).
  std::sort(points.begin(), points.end(), [](const PointEntry& a, const PointEntry& b) {
    return std::tie(a.num_variable_poses, a.point3D_id) <
           std::tie(b.num_variable_poses, b.point3D_id);
  });
  for (const PointEntry& entry : points) {
    Point3D& point = reconstruction_->GetPoint3D(entry.point3D_id);
    if (entry.begin < entry.end) points_added_.insert(entry.point3D_id);
    for (size_t k = entry.begin; k < entry.end; ++k) AddObservation(observations[k], &point);
    if (variable_points.count(entry.point3D_id) > 0) AddPoint(entry.point3D_id, /*constant=*/false);
    if (config_.HasConstantPoint(entry.point3D_id) &&
        problem_->HasParameterBlock(point.xyz.data())) {
      problem_->SetParameterBlockConstant(point.xyz.data());
    }
  }
  ParameterizeCameras();
  // The problem owns only the losses its residual blocks use.
  if (report_.num_reprojection_residual_blocks == 0) {
    delete loss_function_;
    loss_function_ = nullptr;
  }
}

void BundleAdjuster::AddPoseBlocks(image_t image_id) {
  if (pose_blocks_.count(image_id) > 0) return;
  pose_blocks_.insert(image_id);
  Image& image = reconstruction_->GetImage(image_id);
  image.cam_from_world.rotation.normalize();
  double* pose = PoseParameters(image.cam_from_world);
  const bool constant = config_.HasConstantPose(image_id);
  problem_->AddParameterBlock(pose, 7, new PoseCentreManifold);
  if (constant) {
    problem_->SetParameterBlockConstant(pose);
    return;
  }
  const std::vector<int>* coords = config_.ConstantCentreCoords(image_id);
  if (coords == nullptr) return;
  // A step of 1e-6 of the cameras' spread costs a pixel.
  const double weight = 1e6 / centre_spread_;
  const Eigen::Vector3d centre = image.ProjectionCenter();
  for (const int c : *coords) {
    problem_->AddResidualBlock(
        new ceres::AutoDiffCostFunction<CentreCoordinatePrior, 1, 7>(
            new CentreCoordinatePrior{c, centre[c], weight}),
        nullptr, pose);
  }
}

void BundleAdjuster::AddImage(image_t image_id) {
  const Image& image = reconstruction_->GetImage(image_id);
  LOOPSFM_CHECK_MSG(image.registered, "bundle adjustment: image {} is not registered", image_id);
  const Camera& camera = reconstruction_->GetCamera(image.camera_id);
  LOOPSFM_CHECK_EQ(static_cast<int>(camera.params.size()), CameraModelNumParams(camera.model_id));
  config_cameras_.insert(image.camera_id);
  cameras_added_.insert(image.camera_id);
  if (!config_.HasConstantPose(image_id)) AddPoseBlocks(image_id);
}

void BundleAdjuster::AddObservation(const Observation& observation, Point3D* point) {
  Image& image = reconstruction_->GetImage(observation.image_id);
  const Eigen::Vector2d& xy = image.points2D[observation.point2D_idx].xy;
  Camera& camera = reconstruction_->GetCamera(image.camera_id);
  if (config_.HasConstantPose(observation.image_id)) {
    AddConstantPoseResidual(image, xy, point);
  } else if (IsCameraConstant(image.camera_id)) {
    problem_->AddResidualBlock(
        CreateReprojectionErrorConstantCameraCost(camera.model_id, camera.params, xy),
        loss_function_, PoseParameters(image.cam_from_world), point->xyz.data());
  } else {
    problem_->AddResidualBlock(CreateReprojectionErrorCost(camera.model_id, xy), loss_function_,
                               PoseParameters(image.cam_from_world), point->xyz.data(),
                               camera.params.data());
  }
  ++report_.num_reprojection_residual_blocks;
}

bool BundleAdjuster::IsCameraConstant(camera_t camera_id) const {
  const Camera& camera = reconstruction_->GetCamera(camera_id);
  return config_cameras_.count(camera_id) == 0 || config_.HasConstantCamera(camera_id) ||
         static_cast<int>(ConstantCameraParams(camera.model_id, options_).size()) ==
             CameraModelNumParams(camera.model_id);
}

void BundleAdjuster::AddConstantPoseResidual(const Image& image, const Eigen::Vector2d& observed,
                                             Point3D* point) {
  Camera& camera = reconstruction_->GetCamera(image.camera_id);
  LOOPSFM_CHECK_EQ(static_cast<int>(camera.params.size()), CameraModelNumParams(camera.model_id));
  cameras_added_.insert(image.camera_id);
  if (IsCameraConstant(image.camera_id)) {
    problem_->AddResidualBlock(CreateReprojectionErrorConstantPoseCameraCost(
                                   camera.model_id, image.cam_from_world, camera.params, observed),
                               loss_function_, point->xyz.data());
  } else {
    problem_->AddResidualBlock(
        CreateReprojectionErrorConstantPoseCost(camera.model_id, image.cam_from_world, observed),
        loss_function_, point->xyz.data(), camera.params.data());
  }
}

void BundleAdjuster::AddPoint(point3D_t point3D_id, bool constant) {
  Point3D& point = reconstruction_->GetPoint3D(point3D_id);
  points_added_.insert(point3D_id);
  // Observations by registered images outside the config (added with constant poses).
  std::vector<const TrackElement*> outside;
  for (const TrackElement& element : point.track.elements) {
    if (config_.HasImage(element.image_id)) continue;  // added with its image
    if (reconstruction_->GetImage(element.image_id).registered) outside.push_back(&element);
  }
  const size_t cap = options_.max_constant_observations_per_point;
  const size_t num_kept = constant || cap == 0 ? outside.size() : std::min(cap, outside.size());
  for (size_t k = 0; k < num_kept; ++k) {
    // Evenly spread over the track: both ends of a long track stay represented.
    const size_t index = num_kept == outside.size() ? k
                         : num_kept == 1            ? outside.size() / 2
                                         : k * (outside.size() - 1) / (num_kept - 1);
    const TrackElement& element = *outside[index];
    const Image& image = reconstruction_->GetImage(element.image_id);
    AddConstantPoseResidual(image, image.points2D.at(element.point2D_idx).xy, &point);
    ++report_.num_reprojection_residual_blocks;
  }
  if (constant) problem_->SetParameterBlockConstant(point.xyz.data());
}

void BundleAdjuster::ParameterizeCameras() {
  for (const camera_t camera_id : Sorted(cameras_added_)) {
    Camera& camera = reconstruction_->GetCamera(camera_id);
    double* params = camera.params.data();
    if (!problem_->HasParameterBlock(params)) continue;
    const std::vector<int> constant = ConstantCameraParams(camera.model_id, options_);
    const bool all_constant =
        static_cast<int>(constant.size()) == problem_->ParameterBlockSize(params);
    if (config_cameras_.count(camera_id) == 0 || config_.HasConstantCamera(camera_id) ||
        all_constant) {
      problem_->SetParameterBlockConstant(params);
    } else {
      const bool two_focal = VisitCameraModel(
          camera.model_id, [](auto model) { return decltype(model)::kNumFocal == 2; });
      const bool tie_focal = two_focal && options_.refine_focal_length &&
                             options_.keep_aspect_ratio_of_unknown_cameras &&
                             !camera.has_prior_focal_length;
      if (tie_focal) {
        problem_->SetManifold(params, new CameraParamsManifold(
                                          static_cast<int>(camera.params.size()), constant, true));
      } else if (!constant.empty()) {
        problem_->SetManifold(
            params, new ceres::SubsetManifold(static_cast<int>(camera.params.size()), constant));
      }
    }
  }
}

bool BundleAdjuster::HasPoseBlock(image_t image_id) const {
  return pose_blocks_.count(image_id) > 0;
}

double* BundleAdjuster::PoseBlock(image_t image_id) {
  LOOPSFM_CHECK_MSG(problem_ != nullptr, "BundleAdjuster::SetUp must be called first");
  AddPoseBlocks(image_id);
  return PoseParameters(reconstruction_->GetImage(image_id).cam_from_world);
}

double* BundleAdjuster::PointBlock(point3D_t point3D_id) {
  LOOPSFM_CHECK_MSG(problem_ != nullptr, "BundleAdjuster::SetUp must be called first");
  double* xyz = reconstruction_->GetPoint3D(point3D_id).xyz.data();
  if (!problem_->HasParameterBlock(xyz)) {
    problem_->AddParameterBlock(xyz, 3);
    points_added_.insert(point3D_id);
    if (config_.HasConstantPoint(point3D_id)) problem_->SetParameterBlockConstant(xyz);
  }
  return xyz;
}

double* BundleAdjuster::CameraBlock(camera_t camera_id) {
  LOOPSFM_CHECK_MSG(problem_ != nullptr, "BundleAdjuster::SetUp must be called first");
  Camera& camera = reconstruction_->GetCamera(camera_id);
  double* params = camera.params.data();
  if (!problem_->HasParameterBlock(params)) {
    problem_->AddParameterBlock(params, static_cast<int>(camera.params.size()));
    problem_->SetParameterBlockConstant(params);
  }
  return params;
}

void BundleAdjuster::ConfigureSolver(ceres::Solver::Options* solver_options) {
  int num_variable_images = 0;
  for (const image_t image_id : pose_blocks_) {
    if (!problem_->IsParameterBlockConstant(
            PoseParameters(reconstruction_->GetImage(image_id).cam_from_world))) {
      ++num_variable_images;
    }
  }
  report_.num_variable_images = num_variable_images;

  const auto sparse_library = AvailableSparseLibrary();
  BundleLinearSolver choice = options_.linear_solver;
  if (choice == BundleLinearSolver::kAuto) {
    if (num_variable_images <= options_.dense_schur_max_num_images) {
      choice = BundleLinearSolver::kDenseSchur;
    } else if (num_variable_images <= options_.sparse_schur_max_num_images && sparse_library) {
      choice = BundleLinearSolver::kSparseSchur;
    } else {
      choice = BundleLinearSolver::kIterativeSchur;
    }
  }
  if (choice == BundleLinearSolver::kSparseSchur && !sparse_library) {
    choice = BundleLinearSolver::kIterativeSchur;
  }
  switch (choice) {
    case BundleLinearSolver::kAuto:
    case BundleLinearSolver::kDenseSchur:
      solver_options->linear_solver_type = ceres::DENSE_SCHUR;
      break;
    case BundleLinearSolver::kSparseSchur:
      solver_options->linear_solver_type = ceres::SPARSE_SCHUR;
      solver_options->sparse_linear_algebra_library_type = *sparse_library;
      break;
    case BundleLinearSolver::kIterativeSchur:
      solver_options->linear_solver_type = ceres::ITERATIVE_SCHUR;
      solver_options->preconditioner_type = ceres::SCHUR_JACOBI;
      break;
  }
  // Without points there is nothing to eliminate (pose graphs): plain sparse Cholesky.
  if (points_added_.empty()) {
    if (sparse_library) {
      solver_options->linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
      solver_options->sparse_linear_algebra_library_type = *sparse_library;
    } else {
      solver_options->linear_solver_type = ceres::DENSE_QR;
    }
  }

  solver_options->max_num_iterations = options_.max_num_iterations;
  solver_options->max_linear_solver_iterations = options_.max_linear_solver_iterations;
  solver_options->function_tolerance = options_.function_tolerance;
  solver_options->gradient_tolerance = options_.gradient_tolerance;
  solver_options->parameter_tolerance = options_.parameter_tolerance;
  const int threads = options_.num_threads > 0
                          ? options_.num_threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  solver_options->num_threads = threads;
  solver_options->minimizer_progress_to_stdout = options_.print_progress;
  solver_options->logging_type =
      options_.print_progress ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
}

std::vector<camera_t> BundleAdjuster::VariableCameras() const {
  std::vector<camera_t> variable;
  for (const camera_t id : Sorted(cameras_added_)) {
    const double* params = reconstruction_->GetCamera(id).params.data();
    if (problem_->HasParameterBlock(params) && !problem_->IsParameterBlockConstant(params)) {
      variable.push_back(id);
    }
  }
  return variable;
}

bool BundleAdjuster::Solve(Reconstruction* reconstruction) {
  if (problem_ == nullptr) SetUp(reconstruction);
  LOOPSFM_CHECK_MSG(reconstruction == reconstruction_,
                    "BundleAdjuster::Solve: not the reconstruction given to SetUp");
  report_.success = false;
  report_.num_residual_blocks = problem_->NumResidualBlocks();
  report_.num_residuals = problem_->NumResiduals();
  if (problem_->NumResidualBlocks() == 0) {
    report_.termination = "no residuals";
    return false;
  }

  ceres::Solver::Options solver_options;
  ConfigureSolver(&solver_options);
  std::unique_ptr<SettledCallback> settled;
  if (options_.settle_tolerance > 0.0) {
    std::vector<image_t> variable_images;
    for (const image_t id : Sorted(pose_blocks_)) {
      const double* pose = PoseParameters(reconstruction_->GetImage(id).cam_from_world);
      if (!problem_->IsParameterBlockConstant(pose)) variable_images.push_back(id);
    }
    if (variable_images.size() >= 2) {
      settled = std::make_unique<SettledCallback>(*reconstruction_, std::move(variable_images),
                                                  VariableCameras(), options_.settle_tolerance);
      solver_options.callbacks.push_back(settled.get());
      solver_options.update_state_every_iteration = true;
    }
  }
  ceres::Solve(solver_options, problem_.get(), &summary_);

  for (const image_t image_id : pose_blocks_) {
    reconstruction_->GetImage(image_id).cam_from_world.rotation.normalize();
  }
  report_.num_variable_points = 0;
  for (const point3D_t id : points_added_) {
    const double* xyz = reconstruction_->GetPoint3D(id).xyz.data();
    if (problem_->HasParameterBlock(xyz) && !problem_->IsParameterBlockConstant(xyz)) {
      ++report_.num_variable_points;
    }
  }
  report_.num_variable_cameras = static_cast<int>(VariableCameras().size());
  report_.success = summary_.IsSolutionUsable();
  report_.initial_cost = summary_.initial_cost;
  report_.final_cost = summary_.final_cost;
  report_.num_iterations = summary_.num_successful_steps + summary_.num_unsuccessful_steps;
  report_.linear_solver = ceres::LinearSolverTypeToString(summary_.linear_solver_type_used);
  report_.termination = ceres::TerminationTypeToString(summary_.termination_type);
  report_.settled = settled && summary_.termination_type == ceres::USER_SUCCESS;
  report_.time_s = summary_.total_time_in_seconds;
  report_.residual_time_s = summary_.residual_evaluation_time_in_seconds;
  report_.jacobian_time_s = summary_.jacobian_evaluation_time_in_seconds;
  report_.linear_solver_time_s = summary_.linear_solver_time_in_seconds;
  return report_.success;
}

}  // namespace loopsfm
