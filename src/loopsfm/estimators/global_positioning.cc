#include "loopsfm/estimators/global_positioning.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <ceres/ceres.h>
#include <fmt/format.h>

#include "loopsfm/estimators/bearing_rays.h"
#include "loopsfm/estimators/bundle_settled.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// r = direction - scale * (to - from), see global_positioning.h. Parameter blocks: the
// position the direction starts from (3), the one it points to (3), the scale (1).
class DirectionCost {
 public:
  explicit DirectionCost(const Eigen::Vector3d& direction) : direction_(direction) {}

  static ceres::CostFunction* Create(const Eigen::Vector3d& direction) {
    return new ceres::AutoDiffCostFunction<DirectionCost, 3, 3, 3, 1>(
        new DirectionCost(direction));
  }

  template <typename T>
  bool operator()(const T* from, const T* to, const T* scale, T* residuals) const {
    for (int k = 0; k < 3; ++k) {
      residuals[k] = T(direction_[k]) - scale[0] * (to[k] - from[k]);
    }
    return true;
  }

 private:
  Eigen::Vector3d direction_;
};

// The unknowns: parameter blocks live in the positions and scale vectors, whose sizes are
// fixed before the problem is built, so the pointers Ceres holds stay valid. The positions
// are one array, cameras by id and then points by id: Ceres orders the blocks of an
// ordering group by address, and in map nodes that order (and so the rounding of a solve)
// would depend on what the heap held before.
struct Unknowns {
  std::vector<Eigen::Vector3d> positions;
  std::map<image_t, Eigen::Vector3d*> centres;
  std::map<point3D_t, Eigen::Vector3d*> points;
  std::vector<double> scales;
  // Per input observation, its scale (nullptr for observations left out).
  std::vector<double*> observation_scales;
};

// Which observations, points and cameras enter the problem.
struct Selection {
  std::vector<bool> observation_used;
  // Per input observation, the observed direction in the world frame (unit).
  std::vector<Eigen::Vector3d> world_directions;
  std::map<point3D_t, int> num_views;
  std::vector<image_t> cameras;   // sorted
  std::vector<point3D_t> points;  // sorted
  int num_observations = 0;
};

bool IsUsable(const Eigen::Vector3d& v) {
  const double norm = v.norm();
  return std::isfinite(norm) && norm > 1e-12;
}

template <typename... Args>
[[noreturn]] void ThrowBadInput(fmt::format_string<Args...> format, Args&&... args) {
  throw InvalidArgument("global positioning: " +
                        fmt::format(format, std::forward<Args>(args)...));
}

void ValidateInput(const GlobalPositioningInput& input) {
  if (input.observations.empty() && input.camera_directions.empty()) {
    ThrowBadInput("nothing to position: the input has no observations and no camera directions");
  }
  const auto& rotations = input.cam_from_world_rotations;
  for (const auto& [id, q] : rotations) {
    const double norm = q.coeffs().norm();
    if (!(std::isfinite(norm) && norm > 1e-12)) {
      ThrowBadInput("the rotation of image {} is zero or not finite", id);
    }
  }
  std::set<point3D_t> observed;
  for (size_t i = 0; i < input.observations.size(); ++i) {
    const BearingObservation& obs = input.observations[i];
    if (!rotations.count(obs.image_id)) {
      ThrowBadInput("observation {} names image {}, which has no rotation", i, obs.image_id);
    }
    if (!IsUsable(obs.bearing_in_cam)) {
      ThrowBadInput("the bearing of observation {} is zero or not finite", i);
    }
    observed.insert(obs.point_id);
  }
  for (size_t i = 0; i < input.camera_directions.size(); ++i) {
    const CameraPairDirection& dir = input.camera_directions[i];
    if (!rotations.count(dir.image_id1) || !rotations.count(dir.image_id2)) {
      ThrowBadInput("camera direction {} names image {} or {}, without a rotation", i,
                    dir.image_id1, dir.image_id2);
    }
    if (dir.image_id1 == dir.image_id2) {
      ThrowBadInput("camera direction {} joins image {} to itself", i, dir.image_id1);
    }
    if (!IsUsable(dir.direction_in_world)) {
      ThrowBadInput("camera direction {} is zero or not finite", i);
    }
  }
  for (const auto& [id, centre] : input.initial_centres) {
    if (!rotations.count(id)) {
      ThrowBadInput("initial centre given for image {}, which has no rotation", id);
    }
    if (!centre.allFinite()) ThrowBadInput("the initial centre of image {} is not finite", id);
  }
  for (const auto& [id, point] : input.initial_points) {
    if (!observed.count(id)) {
      ThrowBadInput("initial position given for point {}, which no observation names", id);
    }
    if (!point.allFinite()) ThrowBadInput("the initial position of point {} is not finite", id);
  }
}

Selection SelectUsed(const GlobalPositioningInput& input, int min_num_views) {
  Selection selection;
  for (const BearingObservation& obs : input.observations) ++selection.num_views[obs.point_id];
  std::set<image_t> cameras;
  selection.observation_used.resize(input.observations.size(), false);
  selection.world_directions.resize(input.observations.size(), Eigen::Vector3d::Zero());
  for (size_t i = 0; i < input.observations.size(); ++i) {
    const BearingObservation& obs = input.observations[i];
    if (selection.num_views.at(obs.point_id) < min_num_views) continue;
    selection.observation_used[i] = true;
    selection.world_directions[i] =
        input.cam_from_world_rotations.at(obs.image_id).normalized().conjugate() *
        obs.bearing_in_cam.normalized();
    ++selection.num_observations;
    cameras.insert(obs.image_id);
  }
  for (const CameraPairDirection& dir : input.camera_directions) {
    cameras.insert(dir.image_id1);
    cameras.insert(dir.image_id2);
  }
  selection.cameras.assign(cameras.begin(), cameras.end());
  for (const auto& [id, count] : selection.num_views) {
    if (count >= min_num_views) selection.points.push_back(id);
  }
  return selection;
}

// Initial positions in a fixed order (cameras by id, then points by id), so a seed gives
// the same start whatever the input's order.
void InitializePositions(const GlobalPositioningInput& input, const Selection& selection,
                         const GlobalPositioningOptions& options, Unknowns* unknowns) {
  Random random(options.seed);
  const double extent = options.random_init_extent;
  auto draw = [&]() {
    const double x = random.UniformReal(-extent, extent);
    const double y = random.UniformReal(-extent, extent);
    const double z = random.UniformReal(-extent, extent);
    return Eigen::Vector3d(x, y, z);
  };
  unknowns->positions.resize(selection.cameras.size() + selection.points.size());
  Eigen::Vector3d* next = unknowns->positions.data();
  for (image_t id : selection.cameras) {
    const auto it = input.initial_centres.find(id);
    *next = it != input.initial_centres.end() ? it->second : draw();
    unknowns->centres[id] = next++;
  }
  for (point3D_t id : selection.points) {
    const auto it = input.initial_points.find(id);
    *next = it != input.initial_points.end() ? it->second : draw();
    unknowns->points[id] = next++;
  }
}

// The scale that best explains the direction for the given positions, clamped.
double FittedScale(const Eigen::Vector3d& direction, const Eigen::Vector3d& difference,
                   double min_scale) {
  const double squared = difference.squaredNorm();
  if (!(squared > 0.0)) return std::max(1.0, min_scale);
  return std::max(min_scale, direction.dot(difference) / squared);
}

ceres::LossFunction* CreateLoss(PositioningLoss loss, double scale) {
  switch (loss) {
    case PositioningLoss::kTrivial:
      return nullptr;
    case PositioningLoss::kHuber:
      return new ceres::HuberLoss(scale);
    case PositioningLoss::kCauchy:
      return new ceres::CauchyLoss(scale);
  }
  return nullptr;
}

// Adds every used observation and direction; scales go to ordering group 0, points to 1,
// cameras to 2 (the Schur solvers eliminate the scales). A term whose two positions were
// both given starts with the scale that fits them; one with a random end starts at 1, as
// in GLOMAP: every term then pulls at the start, where a fitted scale would leave the
// terms pointing away from their direction at the lower bound, with no pull.
void BuildProblem(const GlobalPositioningInput& input, const Selection& selection,
                  const GlobalPositioningOptions& options, Unknowns* unknowns,
                  ceres::Problem* problem, ceres::ParameterBlockOrdering* ordering) {
  unknowns->scales.assign(selection.num_observations + input.camera_directions.size(), 1.0);
  unknowns->observation_scales.assign(input.observations.size(), nullptr);
  ceres::LossFunction* point_loss = CreateLoss(options.loss, options.loss_scale);
  ceres::LossFunction* direction_loss = new ceres::ScaledLoss(
      CreateLoss(options.loss, options.loss_scale), options.camera_direction_weight,
      ceres::TAKE_OWNERSHIP);
  size_t next_scale = 0;
  auto add = [&](const Eigen::Vector3d& direction, double* from, double* to, bool given,
                 ceres::LossFunction* loss) {
    double* scale = &unknowns->scales[next_scale++];
    const Eigen::Vector3d difference =
        Eigen::Map<const Eigen::Vector3d>(to) - Eigen::Map<const Eigen::Vector3d>(from);
    *scale = given ? FittedScale(direction, difference, options.min_scale)
                   : std::max(1.0, options.min_scale);
    problem->AddResidualBlock(DirectionCost::Create(direction), loss, from, to, scale);
    problem->SetParameterLowerBound(scale, 0, options.min_scale);
    ordering->AddElementToGroup(scale, 0);
    return scale;
  };
  const auto& centres = input.initial_centres;
  for (size_t i = 0; i < input.observations.size(); ++i) {
    if (!selection.observation_used[i]) continue;
    const BearingObservation& obs = input.observations[i];
    const bool given = centres.count(obs.image_id) && input.initial_points.count(obs.point_id);
    unknowns->observation_scales[i] =
        add(selection.world_directions[i], unknowns->centres.at(obs.image_id)->data(),
            unknowns->points.at(obs.point_id)->data(), given, point_loss);
  }
  for (const CameraPairDirection& dir : input.camera_directions) {
    const bool given = centres.count(dir.image_id1) && centres.count(dir.image_id2);
    add(dir.direction_in_world.normalized(), unknowns->centres.at(dir.image_id1)->data(),
        unknowns->centres.at(dir.image_id2)->data(), given, direction_loss);
  }
  // Without point observations no residual block took the point loss.
  if (selection.num_observations == 0) delete point_loss;
  for (auto& [id, point] : unknowns->points) ordering->AddElementToGroup(point->data(), 1);
  for (auto& [id, centre] : unknowns->centres) ordering->AddElementToGroup(centre->data(), 2);
}

ceres::Solver::Options SolverOptions(const GlobalPositioningOptions& options) {
  ceres::Solver::Options solver_options;
  if (options.linear_solver == PositioningLinearSolver::kIterativeSchur) {
    solver_options.linear_solver_type = ceres::ITERATIVE_SCHUR;
    solver_options.preconditioner_type = ceres::SCHUR_JACOBI;
  } else {
    solver_options.linear_solver_type = ceres::SPARSE_SCHUR;
  }
  solver_options.max_num_iterations = options.max_num_iterations;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.num_threads =
      options.num_threads > 0 ? options.num_threads
                              : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  solver_options.logging_type = ceres::SILENT;
  return solver_options;
}

// Ends a solve once the camera centres have settled: two successful steps in a row that
// moved no centre by more than the tolerance times the centres' spread (RMS distance from
// their mean, measured anew each step, as the free scale drifts). Points caught far out
// along nearly parallel rays keep lowering the cost a little for many steps after the
// cameras have converged; RetriangulatePoints moves them in one go instead.
class CentresSettled : public ceres::IterationCallback {
 public:
  CentresSettled(const std::map<image_t, Eigen::Vector3d*>& centres, double tolerance)
      : centres_(centres), tolerance_(tolerance), previous_(Snapshot()) {}

  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    if (summary.iteration == 0 || !summary.step_is_successful) return ceres::SOLVER_CONTINUE;
    std::vector<Eigen::Vector3d> current = Snapshot();
    double max_move = 0.0;
    for (size_t i = 0; i < current.size(); ++i) {
      max_move = std::max(max_move, (current[i] - previous_[i]).norm());
    }
    const double spread = CentreSpread(current);
    previous_ = std::move(current);
    const bool settled = spread > 0.0 && max_move <= tolerance_ * spread;
    num_settled_ = settled ? num_settled_ + 1 : 0;
    return num_settled_ >= 2 ? ceres::SOLVER_TERMINATE_SUCCESSFULLY : ceres::SOLVER_CONTINUE;
  }

 private:
  std::vector<Eigen::Vector3d> Snapshot() const {
    std::vector<Eigen::Vector3d> snapshot;
    for (const auto& [id, centre] : centres_) snapshot.push_back(*centre);
    return snapshot;
  }

  const std::map<image_t, Eigen::Vector3d*>& centres_;
  const double tolerance_;
  std::vector<Eigen::Vector3d> previous_;
  int num_settled_ = 0;
};

// Runs one solve and adds it to the report (the first solve sets the initial cost).
void RunSolver(ceres::Solver::Options solver_options, const Unknowns& unknowns,
               double settle_tolerance, ceres::Problem* problem, GlobalPositioningReport* report) {
  CentresSettled settled(unknowns.centres, settle_tolerance);
  if (settle_tolerance > 0.0) {
    solver_options.update_state_every_iteration = true;
    solver_options.callbacks.push_back(&settled);
  }
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, problem, &summary);
  if (report->num_iterations == 0) report->initial_cost = summary.initial_cost;
  report->num_iterations += static_cast<int>(summary.iterations.size());
  report->final_cost = summary.final_cost;
  report->termination = ceres::TerminationTypeToString(summary.termination_type);
  report->success = summary.IsSolutionUsable();
}

// Per input observation, the angle between its world direction and X_p - c_i (NaN for
// observations left out).
std::vector<double> ObservationAngles(const GlobalPositioningInput& input,
                                      const Selection& selection, const Unknowns& unknowns) {
  std::vector<double> angles(input.observations.size(), std::numeric_limits<double>::quiet_NaN());
  for (size_t i = 0; i < input.observations.size(); ++i) {
    if (!selection.observation_used[i]) continue;
    const BearingObservation& obs = input.observations[i];
    angles[i] = AngleBetween(selection.world_directions[i],
                             *unknowns.points.at(obs.point_id) - *unknowns.centres.at(obs.image_id));
  }
  return angles;
}

// Moves every point to its best ray intersection (bearing_rays.h) where that explains more
// of its observations within max_angle_error_deg, or as many at half the robust cost, and
// fits its observations' scales to the new position. Returns how many points moved.
int RetriangulatePoints(const GlobalPositioningInput& input, const Selection& selection,
                        const GlobalPositioningOptions& options, Unknowns* unknowns) {
  std::map<point3D_t, std::vector<size_t>> observations_of;
  for (size_t i = 0; i < input.observations.size(); ++i) {
    if (selection.observation_used[i]) observations_of[input.observations[i].point_id].push_back(i);
  }
  const std::unique_ptr<ceres::LossFunction> loss(CreateLoss(options.loss, options.loss_scale));
  const double max_angle = options.max_angle_error_deg * M_PI / 180.0;
  int num_moved = 0;
  std::vector<BearingRay> rays;
  for (const auto& [id, observations] : observations_of) {
    rays.clear();
    for (size_t i : observations) {
      rays.push_back({*unknowns->centres.at(input.observations[i].image_id),
                      selection.world_directions[i]});
    }
    Eigen::Vector3d& point = *unknowns->points.at(id);
    const RayFit current = FitRays(point, rays, loss.get(), max_angle);
    const auto best = BestRayIntersection(rays, loss.get(), max_angle);
    if (!best) continue;
    const RayFit& fit = best->second;
    if (fit.num_inliers < current.num_inliers ||
        (fit.num_inliers == current.num_inliers && !(fit.cost < 0.5 * current.cost))) {
      continue;
    }
    point = best->first;
    ++num_moved;
    for (size_t k = 0; k < observations.size(); ++k) {
      *unknowns->observation_scales[observations[k]] =
          FittedScale(rays[k].direction, point - rays[k].origin, options.min_scale);
    }
  }
  return num_moved;
}

// Moves and scales the positions so the centres have zero mean and unit RMS distance.
void NormalizeGauge(Unknowns* unknowns) {
  if (unknowns->centres.empty()) return;
  std::vector<Eigen::Vector3d> centres;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& [id, centre] : unknowns->centres) {
    centres.push_back(*centre);
    mean += *centre;
  }
  mean /= static_cast<double>(centres.size());
  const double spread = CentreSpread(centres);
  const double scale = spread > 0.0 ? 1.0 / spread : 1.0;
  for (Eigen::Vector3d& position : unknowns->positions) position = scale * (position - mean);
}

void CountInput(const GlobalPositioningInput& input, const Selection& selection,
                GlobalPositioningReport* report) {
  report->num_cameras = static_cast<int>(selection.cameras.size());
  report->num_points = static_cast<int>(selection.points.size());
  report->num_unconstrained_cameras =
      static_cast<int>(input.cam_from_world_rotations.size() - selection.cameras.size());
  report->num_skipped_points =
      static_cast<int>(selection.num_views.size() - selection.points.size());
  report->num_observations = selection.num_observations;
  report->num_camera_directions = static_cast<int>(input.camera_directions.size());
}

}  // namespace

void GlobalPositioningOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(loss_scale > 0.0 && std::isfinite(loss_scale),
                         "global positioning: loss_scale must be > 0 (got {})", loss_scale);
  LOOPSFM_REQUIRE_OPTION(random_init_extent > 0.0 && std::isfinite(random_init_extent),
                         "global positioning: random_init_extent must be > 0 (got {})",
                         random_init_extent);
  LOOPSFM_REQUIRE_OPTION(min_scale >= 0.0 && std::isfinite(min_scale),
                         "global positioning: min_scale must be >= 0 (got {})", min_scale);
  LOOPSFM_REQUIRE_OPTION(min_num_views_per_point >= 1,
                         "global positioning: min_num_views_per_point must be >= 1 (got {})",
                         min_num_views_per_point);
  LOOPSFM_REQUIRE_OPTION(camera_direction_weight > 0.0 && std::isfinite(camera_direction_weight),
                         "global positioning: camera_direction_weight must be > 0 (got {})",
                         camera_direction_weight);
  LOOPSFM_REQUIRE_OPTION(max_angle_error_deg > 0.0 && max_angle_error_deg <= 180.0,
                         "global positioning: max_angle_error_deg must be in (0, 180] (got {})",
                         max_angle_error_deg);
  LOOPSFM_REQUIRE_OPTION(max_num_iterations > 0,
                         "global positioning: max_num_iterations must be > 0 (got {})",
                         max_num_iterations);
  LOOPSFM_REQUIRE_OPTION(settle_tolerance >= 0.0,
                         "global positioning: settle_tolerance must be >= 0 (got {})",
                         settle_tolerance);
  LOOPSFM_REQUIRE_OPTION(function_tolerance >= 0.0,
                         "global positioning: function_tolerance must be >= 0 (got {})",
                         function_tolerance);
}

GlobalPositioningResult SolveGlobalPositioning(const GlobalPositioningInput& input,
                                               const GlobalPositioningOptions& options) {
  options.Check();
  ValidateInput(input);
  Timer timer;
  GlobalPositioningResult result;
  GlobalPositioningReport& report = result.report;
  const Selection selection = SelectUsed(input, options.min_num_views_per_point);
  CountInput(input, selection, &report);
  if (selection.cameras.empty()) {
    result.observation_angles.assign(input.observations.size(),
                                     std::numeric_limits<double>::quiet_NaN());
    report.termination = "nothing to position: no point has enough views";
    report.time_s = timer.ElapsedSeconds();
    return result;
  }

  Unknowns unknowns;
  InitializePositions(input, selection, options, &unknowns);
  ceres::Problem problem;
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  BuildProblem(input, selection, options, &unknowns, &problem, ordering.get());
  ceres::Solver::Options solver_options = SolverOptions(options);
  solver_options.linear_solver_ordering = ordering;
  RunSolver(solver_options, unknowns, options.settle_tolerance, &problem, &report);

  const double max_angle = options.max_angle_error_deg * M_PI / 180.0;
  if (report.success && options.retriangulate_points) {
    report.num_retriangulated_points = RetriangulatePoints(input, selection, options, &unknowns);
    if (report.num_retriangulated_points > 0) {
      RunSolver(solver_options, unknowns, options.settle_tolerance, &problem, &report);
    }
  }
  result.observation_angles = ObservationAngles(input, selection, unknowns);
  for (double angle : result.observation_angles) {
    if (angle > max_angle) ++report.num_large_angle_observations;
  }
  if (options.normalize_gauge) NormalizeGauge(&unknowns);
  for (const auto& [id, centre] : unknowns.centres) result.camera_centres[id] = *centre;
  for (const auto& [id, point] : unknowns.points) result.points[id] = *point;
  report.time_s = timer.ElapsedSeconds();
  return result;
}

std::map<image_t, Rigid3d> CamFromWorldFromCentres(
    const std::map<image_t, Eigen::Quaterniond>& cam_from_world_rotations,
    const std::map<image_t, Eigen::Vector3d>& camera_centres) {
  std::map<image_t, Rigid3d> poses;
  for (const auto& [id, centre] : camera_centres) {
    const auto it = cam_from_world_rotations.find(id);
    LOOPSFM_CHECK_MSG(it != cam_from_world_rotations.end(), "no rotation for image {}", id);
    const Eigen::Quaterniond rotation = it->second.normalized();
    poses[id] = Rigid3d(rotation, -(rotation * centre));
  }
  return poses;
}

}  // namespace loopsfm
