#pragma once
// Bundle adjustment with Ceres: jointly refines image poses, 3D points and, optionally,
// camera intrinsics by minimising robustified reprojection errors.
//
// The mapper uses it twice: a local bundle over the newest images after each registration
// (few iterations) and a global bundle whenever the model has grown by a set fraction (over
// a window of its most recent frames once it is large, the rest held constant). Loop
// closing adds its own terms (point distances, relative poses) to the same problem:
//
//   BundleAdjuster adjuster(options, config);
//   adjuster.SetUp(&reconstruction);
//   adjuster.problem().AddResidualBlock(PointDistanceCost::Create(d, w), nullptr,
//                                       adjuster.PointBlock(id_a), adjuster.PointBlock(id_b));
//   adjuster.Solve(&reconstruction);
//
// Parameter blocks point straight into the Reconstruction (quaternion coefficients, x, y,
// z, w; translation; point xyz; camera params), so Solve updates it in place. The
// Reconstruction must not add or remove cameras, images or points between SetUp and Solve.

#include <memory>
#include <string>
#include <unordered_map>
#include <optional>
#include <unordered_set>
#include <vector>

#include <ceres/ceres.h>

#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

enum class BundleLossFunction { kTrivial, kHuber, kSoftL1, kCauchy };

enum class BundleLinearSolver {
  kAuto,            // by the number of variable images, see the options below
  kDenseSchur,      // small problems
  kSparseSchur,     // medium problems (SuiteSparse or Eigen sparse Cholesky)
  kIterativeSchur,  // large problems (preconditioned conjugate gradients, Schur-Jacobi)
};

struct BundleAdjustmentOptions {
  // Robust loss on each observation's squared reprojection error.
  BundleLossFunction loss_function = BundleLossFunction::kSoftL1;
  // Pixel error at which the robust loss starts to down-weight an observation.
  double loss_function_scale = 1.0;
  // Refine the focal length(s) of cameras used by images in the problem.
  bool refine_focal_length = false;
  // Refine the principal point (badly conditioned for narrow fields of view).
  bool refine_principal_point = false;
  // Refine the distortion parameters of the camera model.
  bool refine_extra_params = false;
  // For cameras without a prior focal length whose model has fx and fy: refine them as one
  // focal length, fx / fy held at its initial value (square pixels for a guessed camera; an
  // unconstrained aspect ratio drifts with the scene's structure). Cameras with a prior
  // refine fx and fy separately, as COLMAP does.
  bool keep_aspect_ratio_of_unknown_cameras = true;
  // Observations of a variable point by images outside the config (constant poses) that
  // enter the problem, at most, spread evenly over its track (0: all). They only anchor the
  // point; a long track's dozens of them cost residuals without constraining the local
  // bundle more.
  int max_constant_observations_per_point = 0;
  // Levenberg-Marquardt iterations (COLMAP: 100 for global, 25 for local bundles).
  int max_num_iterations = 100;
  // Stop when the relative cost decrease of a step falls below this.
  double function_tolerance = 1e-6;
  // Stop when the max-norm of the gradient falls below this.
  double gradient_tolerance = 1e-10;
  // Stop when the relative step size falls below this.
  double parameter_tolerance = 1e-8;
  // Stop once the cameras have settled: two successful steps in a row after which no
  // variable camera centre moved by more than this fraction of the centres' spread (RMS
  // distance from their mean), no camera turned by more than this many radians, and no
  // refined intrinsic parameter changed by more than this fraction of max(|value|, 1).
  // Far points, whose depth the images barely constrain, creep along their rays for dozens
  // of steps after the cameras have converged, each step lowering the cost by just more
  // than function_tolerance; this ends those tails. 0: off (Ceres' tolerances alone).
  double settle_tolerance = 0.0;
  // Conjugate-gradient iterations per step of the iterative Schur solver.
  int max_linear_solver_iterations = 200;
  // Linear solver; kAuto picks one by the number of variable images.
  BundleLinearSolver linear_solver = BundleLinearSolver::kAuto;
  // kAuto: dense Schur below this many variable images.
  int dense_schur_max_num_images = 50;
  // kAuto: iterative Schur above this many variable images (sparse Schur between).
  int sparse_schur_max_num_images = 1000;
  // Threads for Jacobian evaluation and the linear solver; <= 0: all hardware threads.
  int num_threads = -1;
  // Print Ceres' per-iteration progress to stdout (debugging only).
  bool print_progress = false;

  // Defaults for the local bundle after each registration (fewer iterations, at most 4
  // anchoring observations per point, ended once the cameras have settled).
  static BundleAdjustmentOptions Local();
  // Defaults for the global bundle.
  static BundleAdjustmentOptions Global();
  // Throws InvalidArgument on out-of-range values.
  void Check() const;
};

// Which parts of a Reconstruction enter the problem and which of them are held constant.
// Every observation of a 3D point seen by an image of the config is added; observations of
// those points by other registered images enter with constant poses, so the points stay
// consistent with the whole model (local bundles).
class BundleAdjustmentConfig {
 public:
  // Adds a registered image: its observations of 3D points become residuals.
  void AddImage(image_t image_id) { image_ids_.insert(image_id); }
  bool HasImage(image_t image_id) const { return image_ids_.count(image_id) > 0; }
  void RemoveImage(image_t image_id);
  const std::unordered_set<image_t>& ImageIds() const { return image_ids_; }
  size_t NumImages() const { return image_ids_.size(); }

  // The whole pose (rotation and translation) of an image stays fixed.
  void SetConstantPose(image_t image_id) { constant_poses_.insert(image_id); }
  void SetVariablePose(image_t image_id) { constant_poses_.erase(image_id); }
  bool HasConstantPose(image_t image_id) const { return constant_poses_.count(image_id) > 0; }

  // Holds some coordinates (0, 1, 2) of an image's projection centre (world frame) at their
  // start values, e.g. one of the second gauge image's to fix the scale; the rotation stays
  // free. Held by a stiff prior (a step of 1e-6 of the config's camera spread costs a pixel),
  // which keeps the pose block's size and so Ceres' fixed-size Schur kernel. The centre, not
  // the translation t = -R c: t also moves when the image turns, by as much as the world's
  // origin is far away, so holding a coordinate of t lets a slight turn of the second image
  // stand in for a change of scale (after mapping, block.mp4's gauge images lay 50 units from
  // the origin, and a bundle after a loop closing grew the model 7x in 100 iterations).
  void SetConstantCentreCoords(image_t image_id, std::vector<int> coords);
  void RemoveConstantCentreCoords(image_t image_id) { constant_centre_.erase(image_id); }
  const std::vector<int>* ConstantCentreCoords(image_t image_id) const;

  // Adds a point with all its observations by registered images, even if none of its
  // images is in the config (their poses are then constant).
  void AddVariablePoint(point3D_t point3D_id);
  // Holds a point fixed where images of the config observe it (its observations by other
  // images are then not added: they would constrain nothing).
  void AddConstantPoint(point3D_t point3D_id);
  bool HasVariablePoint(point3D_t id) const { return variable_points_.count(id) > 0; }
  bool HasConstantPoint(point3D_t id) const { return constant_points_.count(id) > 0; }
  void RemoveVariablePoint(point3D_t id) { variable_points_.erase(id); }
  void RemoveConstantPoint(point3D_t id) { constant_points_.erase(id); }
  const std::unordered_set<point3D_t>& VariablePoints() const { return variable_points_; }
  const std::unordered_set<point3D_t>& ConstantPoints() const { return constant_points_; }

  // Only observations of these points enter (a subset bundle: the cameras move with a
  // fraction of the residuals, the other points stay where they are). Not called: all.
  void RestrictToPoints(std::unordered_set<point3D_t> point3D_ids) {
    point_subset_ = std::move(point3D_ids);
  }
  bool InPointSubset(point3D_t id) const {
    return !point_subset_ || point_subset_->count(id) > 0;
  }

  // Intrinsics of a camera stay fixed whatever the refine_* options say.
  void SetConstantCamera(camera_t camera_id) { constant_cameras_.insert(camera_id); }
  void SetVariableCamera(camera_t camera_id) { constant_cameras_.erase(camera_id); }
  bool HasConstantCamera(camera_t camera_id) const {
    return constant_cameras_.count(camera_id) > 0;
  }

 private:
  std::unordered_set<image_t> image_ids_;
  std::unordered_set<image_t> constant_poses_;
  std::unordered_map<image_t, std::vector<int>> constant_centre_;
  std::unordered_set<point3D_t> variable_points_;
  std::unordered_set<point3D_t> constant_points_;
  std::unordered_set<camera_t> constant_cameras_;
  std::optional<std::unordered_set<point3D_t>> point_subset_;
};

// Fixes the seven-degree-of-freedom gauge of a reconstruction through two of its images:
// the first image's pose is constant, and the coordinate of the second's centre that best
// fixes the scale (the largest component of the baseline between the two centres).
void FixGaugeWithTwoImages(const Reconstruction& reconstruction, image_t first_image_id,
                           image_t second_image_id, BundleAdjustmentConfig* config);

// The registered image whose centre is farthest from `from`'s (ties: the lowest id), or
// `fallback` when none is farther than it: the second gauge image that holds the scale over
// the whole model's extent. A short baseline (the initial pair's, or two consecutive frames')
// holds it weakly; where the frames there fit the rest badly, a bundle can grow the whole
// model about the first one, lowering its cost a little with every step.
image_t FarthestRegisteredImage(const Reconstruction& reconstruction, image_t from,
                                image_t fallback);

struct BundleAdjustmentReport {
  // True when Ceres ended with a usable solution (converged or ran out of iterations).
  bool success = false;
  // Half the sum of the robustified squared residuals, before and after.
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int num_iterations = 0;
  // Scalar residuals and residual blocks (reprojection terms plus extra ones).
  int num_residuals = 0;
  int num_residual_blocks = 0;
  int num_reprojection_residual_blocks = 0;
  // Parameter blocks in the problem that are free.
  int num_variable_images = 0;
  int num_variable_points = 0;
  int num_variable_cameras = 0;
  std::string linear_solver;
  std::string termination;
  // The solve ended because the cameras had settled (settle_tolerance).
  bool settled = false;
  double time_s = 0.0;
  // Where the time went: residuals and Jacobians evaluated, linear systems solved.
  double residual_time_s = 0.0;
  double jacobian_time_s = 0.0;
  double linear_solver_time_s = 0.0;
};

class BundleAdjuster {
 public:
  BundleAdjuster(const BundleAdjustmentOptions& options, const BundleAdjustmentConfig& config);
  ~BundleAdjuster();
  BundleAdjuster(const BundleAdjuster&) = delete;
  BundleAdjuster& operator=(const BundleAdjuster&) = delete;

  // Builds the problem: reprojection residuals, manifolds and constant blocks. Call at most
  // once; Solve calls it when it has not been called.
  void SetUp(Reconstruction* reconstruction);
  bool IsSetUp() const { return problem_ != nullptr; }

  // Runs the solver and writes the result into the reconstruction (normalised quaternions).
  // Returns report().success.
  bool Solve(Reconstruction* reconstruction);

  // The Ceres problem, after SetUp, for extra residual blocks and constant/variable blocks.
  ceres::Problem& problem();

  // Parameter blocks. Each is added to the problem on first use (so extra terms can refer
  // to images and points with no observations in the config); a block added this way is
  // constant when the config says so (constant pose, constant point, constant camera) and
  // variable otherwise. Must be called after SetUp.
  double* PoseBlock(image_t image_id);        // 7: quaternion x, y, z, w, translation
  double* PointBlock(point3D_t point3D_id);   // 3
  double* CameraBlock(camera_t camera_id);    // Model::kNumParams
  // Whether a pose's block is in the problem. Poses held constant by the config get
  // constant-pose reprojection terms and no block until PoseBlock asks for it.
  bool HasPoseBlock(image_t image_id) const;

  const BundleAdjustmentReport& report() const { return report_; }
  // Ceres' full report, for logging.
  std::string FullReport() const { return summary_.FullReport(); }

 private:
  // An observation of a point by an image of the config.
  struct Observation {
    point3D_t point3D_id;
    image_t image_id;
    uint32_t point2D_idx;
  };
  // An image of the config: its camera and, unless its pose is held constant, its pose block.
  void AddImage(image_t image_id);
  void AddObservation(const Observation& observation, Point3D* point);
  void AddPoint(point3D_t point3D_id, bool constant);
  // The residual of an observation by an image whose pose is held constant.
  void AddConstantPoseResidual(const Image& image, const Eigen::Vector2d& observed,
                               Point3D* point);
  // Whether the camera's parameters stay fixed in this problem (they are then data in the
  // residuals, not a parameter block).
  bool IsCameraConstant(camera_t camera_id) const;
  // Cameras whose parameters are a variable block of the problem, in id order.
  std::vector<camera_t> VariableCameras() const;
  void AddPoseBlocks(image_t image_id);
  void ParameterizeCameras();
  void ConfigureSolver(ceres::Solver::Options* solver_options);

  BundleAdjustmentOptions options_;
  BundleAdjustmentConfig config_;
  Reconstruction* reconstruction_ = nullptr;
  std::unique_ptr<ceres::Problem> problem_;
  // Shared by all reprojection residuals; owned by the problem.
  ceres::LossFunction* loss_function_ = nullptr;
  std::unordered_set<image_t> pose_blocks_;
  // Length unit of the centre priors (CentreSpread of the config's images).
  double centre_spread_ = 1.0;
  std::unordered_set<point3D_t> points_added_;
  std::unordered_set<camera_t> cameras_added_;
  // Cameras used by images of the config: the ones whose intrinsics may be refined.
  std::unordered_set<camera_t> config_cameras_;
  ceres::Solver::Summary summary_;
  BundleAdjustmentReport report_;
};

}  // namespace loopsfm
