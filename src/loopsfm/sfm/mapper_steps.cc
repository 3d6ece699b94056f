// MapperState's registration and bundle adjustment steps.

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "loopsfm/estimators/absolute_pose.h"
#include "loopsfm/estimators/bundle_adjustment.h"
#include "loopsfm/estimators/cost_functions/focal_prior.h"
#include "loopsfm/estimators/reprojection.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

namespace {

// 2D-3D correspondences of one frame, in the order RANSAC sees them.
struct Correspondences {
  std::vector<Eigen::Vector2d> points2D;
  std::vector<Eigen::Vector3d> points3D;
  size_t size() const { return points2D.size(); }
};

// Every 3D point of each keypoint's track is a candidate: where a track holds several,
// RANSAC keeps the one that fits.
Correspondences TrackCorrespondences(const MapperState& state, image_t image_id) {
  const Reconstruction& rec = state.reconstruction();
  const Image& image = rec.GetImage(image_id);
  Correspondences all;
  for (point2D_t idx = 0; idx < image.points2D.size(); ++idx) {
    const int track = state.TrackOf(image_id, idx);
    if (track < 0) continue;
    for (point3D_t point : state.PointsOfTrack(track)) {
      all.points2D.push_back(image.points2D[idx].xy);
      all.points3D.push_back(rec.GetPoint3D(point).xyz);
    }
  }
  return all;
}

// Enough inliers, absolutely and as a share of the correspondences, to register a frame.
bool Registrable(const AbsolutePoseReport& pose, size_t num_correspondences,
                 const IncrementalMapperOptions& options) {
  return pose.success && pose.num_inliers >= options.abs_pose_min_num_inliers &&
         pose.num_inliers >= options.abs_pose_min_inlier_ratio * num_correspondences;
}

// `result` replaced by the pose estimated from the points the frame shares with its
// neighbours in capture order, with its inliers counted over all the correspondences;
// false (and `result` untouched) where those points give no registrable pose.
bool PoseFromNeighbours(const MapperState& state, image_t image_id,
                        const std::vector<std::pair<point2D_t, point3D_t>>& neighbour,
                        const Correspondences& all,
                        const AbsolutePoseEstimationOptions& pose_options, Random& random,
                        AbsolutePoseReport* result, int* num_fit) {
  const Reconstruction& rec = state.reconstruction();
  const Image& image = rec.GetImage(image_id);
  const Camera& camera = rec.GetCamera(image.camera_id);
  Correspondences near;
  for (const auto& [idx, point] : neighbour) {
    near.points2D.push_back(image.points2D[idx].xy);
    near.points3D.push_back(rec.GetPoint3D(point).xyz);
  }
  const AbsolutePoseReport local =
      EstimateAbsolutePose(near.points2D, near.points3D, camera, pose_options, random);
  *num_fit = local.num_inliers;
  if (!Registrable(local, near.size(), state.options())) return false;
  result->cam_from_world = local.cam_from_world;
  result->refinement_failed = local.refinement_failed;
  result->num_inliers = 0;
  const double max_error_sq = pose_options.max_error_px * pose_options.max_error_px;
  for (size_t k = 0; k < all.size(); ++k) {
    result->inlier_mask[k] = CalculateSquaredReprojectionError(
                                 all.points2D[k], all.points3D[k], local.cam_from_world,
                                 camera) <= max_error_sq;
    result->num_inliers += result->inlier_mask[k];
  }
  return true;
}

// The diagnostic second round (record_alternate_poses): a RANSAC of its own over the
// correspondences the registration rejected (for a keypoint whose track holds several
// points, the candidates that did not fit), and how far its pose is from the first.
RegistrationRounds AlternatePose(const MapperState& state, image_t image_id,
                                 const Correspondences& all, const AbsolutePoseReport& first,
                                 const AbsolutePoseEstimationOptions& pose_options) {
  const IncrementalMapperOptions& options = state.options();
  const Image& image = state.reconstruction().GetImage(image_id);
  RegistrationRounds rounds;
  rounds.frame = image.name;
  rounds.num_correspondences = static_cast<int>(all.size());
  rounds.num_inliers = first.num_inliers;
  Correspondences rest;
  for (size_t k = 0; k < all.size(); ++k) {
    if (first.inlier_mask[k]) continue;
    rest.points2D.push_back(all.points2D[k]);
    rest.points3D.push_back(all.points3D[k]);
  }
  rounds.second_num_correspondences = static_cast<int>(rest.size());
  if (static_cast<int>(rest.size()) < options.abs_pose_min_num_inliers) return rounds;
  Random second_random(options.seed ^ (0x9e3779b97f4a7c15ULL * image_id));
  const AbsolutePoseReport second =
      EstimateAbsolutePose(rest.points2D, rest.points3D,
                           state.reconstruction().GetCamera(image.camera_id), pose_options,
                           second_random);
  rounds.second_num_inliers = second.success ? second.num_inliers : 0;
  rounds.second_pose_found = Registrable(second, rest.size(), options);
  if (second.success) {
    const Rigid3d first_from_second = first.cam_from_world * second.cam_from_world.Inverse();
    rounds.second_centre_distance = (first.cam_from_world.Inverse().translation -
                                     second.cam_from_world.Inverse().translation).norm();
    rounds.second_rotation_deg =
        Eigen::AngleAxisd(first_from_second.rotation).angle() * 180.0 / M_PI;
  }
  return rounds;
}

}  // namespace

bool MapperState::RegisterImage(image_t image_id, Random& random, MapperReport* report) {
  Timer timer;
  const Image& image = reconstruction_.GetImage(image_id);
  const Correspondences all = TrackCorrespondences(*this, image_id);
  AbsolutePoseEstimationOptions pose_options;
  pose_options.max_error_px = options_.abs_pose_max_error_px;
  pose_options.min_num_inliers = options_.abs_pose_min_num_inliers;
  AbsolutePoseReport result = EstimateAbsolutePose(
      all.points2D, all.points3D, reconstruction_.GetCamera(image.camera_id), pose_options,
      random);
  const bool accepted = Registrable(result, all.size(), options_);
  const std::vector<std::pair<point2D_t, point3D_t>> neighbour =
      accepted ? NeighbourCorrespondences(image_id)
               : std::vector<std::pair<point2D_t, point3D_t>>{};
  const NeighbourAgreement agreement =
      AgreementWithNeighbours(image_id, result.cam_from_world, neighbour);
  if (agreement.Disagrees()) {
    // The pose does not see what the frames next to it in capture order see: most of its
    // inliers are look-alike structure elsewhere in the model (a twin facade). Estimate it
    // again from the points it shares with those frames, as a tracker would.
    ++report->num_poses_against_neighbours;
    const int num_inliers = result.num_inliers;
    int num_fit = 0;
    if (!PoseFromNeighbours(*this, image_id, neighbour, all, pose_options, random, &result,
                            &num_fit)) {
      report->seconds_registration += timer.ElapsedSeconds();
      spdlog::debug("could not register {}: its pose ({} of {} correspondences) fits {} of {} "
                    "points of the frames next to it, and those points give no pose ({} fit)",
                    image.name, num_inliers, all.size(), agreement.num_fit,
                    agreement.num_checked, num_fit);
      return false;
    }
    ++report->num_poses_from_neighbours;
    spdlog::debug("{}: its pose ({} of {} correspondences) fits {} of {} points of the frames "
                  "next to it; registered from those points ({} fit)",
                  image.name, num_inliers, all.size(), agreement.num_fit,
                  agreement.num_checked, num_fit);
  }
  report->seconds_registration += timer.ElapsedSeconds();
  if (accepted && result.refinement_failed) {
    ++report->num_failed_pose_refinements;
    spdlog::debug("pose refinement of {} failed; its RANSAC pose is used", image.name);
  }
  if (!accepted) {
    spdlog::debug("could not register {}: {} of {} correspondences fit", image.name,
                  result.num_inliers, all.size());
    return false;
  }
  reconstruction_.GetImage(image_id).cam_from_world = result.cam_from_world;
  reconstruction_.RegisterImage(image_id);
  if (options_.record_alternate_poses) {
    report->registrations.push_back(AlternatePose(*this, image_id, all, result, pose_options));
  }
  return true;
}

std::vector<image_t> MapperState::UndoPosesAgainstNeighbours(image_t image_id,
                                                             MapperReport* report) {
  Timer timer;
  std::vector<image_t> undone;
  for (const auto& [distance, other, pair] : RegisteredPartnersNear(image_id)) {
    if (other == gauge1_ || other == gauge2_) continue;
    const NeighbourAgreement agreement = AgreementWithNeighbours(
        other, reconstruction_.GetImage(other).cam_from_world, NeighbourCorrespondences(other));
    if (!agreement.Disagrees()) continue;
    spdlog::debug("{}: its pose fits {} of {} points of the frames next to it now that {} is "
                  "registered; registered again later",
                  reconstruction_.GetImage(other).name, agreement.num_fit, agreement.num_checked,
                  reconstruction_.GetImage(image_id).name);
    reconstruction_.DeRegisterImage(other);
    undone.push_back(other);
  }
  report->num_poses_undone_by_neighbours += static_cast<int>(undone.size());
  report->seconds_registration += timer.ElapsedSeconds();
  return undone;
}

namespace {

void FixGauge(const Reconstruction& reconstruction, image_t gauge1, image_t gauge2,
              BundleAdjustmentConfig* config) {
  if (config->HasImage(gauge1) && config->HasImage(gauge2)) {
    // The config must also have a constant image when all registered frames are in it.
    FixGaugeWithTwoImages(reconstruction, gauge1, gauge2, config);
  } else if (config->HasImage(gauge1)) {
    config->SetConstantPose(gauge1);
  }
}

// The 3D points the registered ones of `frames` observe, each once; `observations` gets
// how many observations of points those frames have.
template <typename Frames>
std::vector<point3D_t> PointsSeenBy(const Reconstruction& reconstruction, const Frames& frames,
                                    size_t* observations = nullptr) {
  std::vector<point3D_t> points;
  for (image_t id : frames) {
    if (!reconstruction.IsRegistered(id)) continue;
    for (const Point2D& p : reconstruction.GetImage(id).points2D) {
      if (p.HasPoint3D()) points.push_back(p.point3D_id);
    }
  }
  if (observations) *observations = points.size();
  std::sort(points.begin(), points.end());
  points.erase(std::unique(points.begin(), points.end()), points.end());
  return points;
}

// Ceres copies the solution into the parameter blocks only when it is usable (solver.cc:
// StateVectorToParameterBlocks of the original state otherwise), so a failed solve leaves
// the model as it was.
bool ReportSolve(BundleAdjuster& adjuster, Reconstruction* reconstruction, const char* what,
                 MapperReport* report) {
  if (adjuster.Solve(reconstruction)) return true;
  ++report->num_failed_bundles;
  spdlog::warn("{} bundle adjustment failed ({}); the model keeps its previous state", what,
               adjuster.report().termination);
  return false;
}

}  // namespace

bool MapperState::LocalBundle(image_t image_id, MapperReport* report) {
  Timer timer;
  // The frames sharing most 3D points with the new one.
  std::unordered_map<image_t, size_t> shared;
  for (const Point2D& p : reconstruction_.GetImage(image_id).points2D) {
    if (!p.HasPoint3D()) continue;
    for (const TrackElement& el : reconstruction_.GetPoint3D(p.point3D_id).track.elements) {
      if (el.image_id != image_id) ++shared[el.image_id];
    }
  }
  std::vector<std::pair<size_t, image_t>> ranked;
  for (const auto& [id, count] : shared) ranked.push_back({count, id});
  std::sort(ranked.begin(), ranked.end(), std::greater<>());
  BundleAdjustmentConfig config;
  config.AddImage(image_id);
  for (size_t i = 0; i < ranked.size() && i < static_cast<size_t>(options_.local_ba_num_images); ++i) {
    config.AddImage(ranked[i].second);
  }
  FixGauge(reconstruction_, gauge1_, gauge2_, &config);
  for (const auto& [id, camera] : reconstruction_.Cameras()) config.SetConstantCamera(id);
  BundleAdjustmentOptions ba_options = BundleAdjustmentOptions::Local();
  ba_options.num_threads = options_.num_threads > 0 ? options_.num_threads : -1;
  bool ok = false;
  {  // the problem is torn down within the step's time
    BundleAdjuster adjuster(ba_options, config);
    ok = ReportSolve(adjuster, &reconstruction_, "local", report);
    report->num_local_ba_iterations += adjuster.report().num_iterations;
    report->num_local_ba_residuals += adjuster.report().num_residual_blocks;
  }
  // Points of the local frames may have moved: check them.
  FilterPoints(PointsSeenBy(reconstruction_, config.ImageIds()));
  ++report->num_local_ba;
  report->seconds_local_ba += timer.ElapsedSeconds();
  return ok;
}

bool MapperState::GlobalBundle(MapperReport* report, const GlobalBundleScope& scope) {
  Timer timer;
  BundleAdjustmentConfig config;
  if (scope.frames) {
    for (image_t id : *scope.frames) {
      if (reconstruction_.IsRegistered(id)) config.AddImage(id);
    }
  } else {
    for (image_t id : reconstruction_.RegImageIds()) config.AddImage(id);
  }
  // A window's fixed frames hold the gauge.
  const bool whole = config.NumImages() == reconstruction_.NumRegImages();
  if (whole) FixGaugeWithTwoImages(reconstruction_, gauge1_, ScaleGaugeImage(), &config);
  if (scope.points) config.RestrictToPoints(*scope.points);
  BundleAdjustmentOptions ba_options = BundleAdjustmentOptions::Global();
  ba_options.num_threads = options_.num_threads > 0 ? options_.num_threads : -1;
  if (scope.settle_tolerance) ba_options.settle_tolerance = *scope.settle_tolerance;
  if (scope.function_tolerance) ba_options.function_tolerance = *scope.function_tolerance;
  if (whole) {
    SetIntrinsicsRefinement(&config, &ba_options);
  } else {
    for (const auto& [id, camera] : reconstruction_.Cameras()) config.SetConstantCamera(id);
    // As in local bundles: a point seen on every lap of a walk would otherwise bring its
    // observations from all the earlier laps, and the window's bundle would grow with them.
    ba_options.max_constant_observations_per_point =
        BundleAdjustmentOptions::Local().max_constant_observations_per_point;
  }
  bool ok = false;
  {  // the problem is torn down within the step's time
    BundleAdjuster adjuster(ba_options, config);
    if (ba_options.refine_focal_length) AddFocalPriors(config, adjuster);
    if (scope.add_terms) {
      if (!adjuster.IsSetUp()) adjuster.SetUp(&reconstruction_);
      scope.add_terms(adjuster);
    }
    ok = ReportSolve(adjuster, &reconstruction_, "global", report);
    const BundleAdjustmentReport& solved = adjuster.report();
    spdlog::debug("{} bundle: {} frames, {} points, {} residual blocks, {} iterations{}, cost "
                  "{:.6g} -> {:.6g}, {:.1f} s (residuals {:.1f} s, Jacobians {:.1f} s, {} {:.1f} s)",
                  whole ? "global" : "window", solved.num_variable_images,
                  solved.num_variable_points, solved.num_residual_blocks, solved.num_iterations,
                  solved.settled ? " (cameras settled)" : "", solved.initial_cost,
                  solved.final_cost, timer.ElapsedSeconds(), solved.residual_time_s,
                  solved.jacobian_time_s, solved.linear_solver, solved.linear_solver_time_s);
    report->num_global_ba_iterations += solved.num_iterations;
    report->num_global_ba_residuals += solved.num_residual_blocks;
  }
  ++report->num_global_ba;
  report->seconds_global_ba += timer.ElapsedSeconds();
  return ok;
}

void MapperState::SetIntrinsicsRefinement(BundleAdjustmentConfig* config,
                                          BundleAdjustmentOptions* ba_options) const {
  // A camera's parameters are refined by what its kind of intrinsics asks for, and only
  // once the model has enough frames to constrain them.
  const size_t num_frames = reconstruction_.NumRegImages();
  for (const auto& [id, camera] : reconstruction_.Cameras()) {
    const IntrinsicsRefinement& asked =
        camera.has_prior_focal_length ? options_.refine_known : options_.refine_unknown;
    const bool focal = asked.focal_length && num_frames >= 5;
    const bool pp = asked.principal_point && num_frames >= 10;
    const bool distortion = asked.distortion && num_frames >= 10;
    if (!focal && !pp && !distortion) {
      config->SetConstantCamera(id);
      continue;
    }
    // One set of refine flags serves every variable camera; both kinds of camera in one model
    // with different requests is not supported (the flags set both alike).
    ba_options->refine_focal_length |= focal;
    ba_options->refine_principal_point |= pp;
    ba_options->refine_extra_params |= distortion;
  }
}

void MapperState::AddFocalPriors(const BundleAdjustmentConfig& config, BundleAdjuster& adjuster) {
  if (options_.focal_prior_sigma_log <= 0) return;
  adjuster.SetUp(&reconstruction_);
  for (const Camera& start : input_.cameras) {
    if (start.has_prior_focal_length || config.HasConstantCamera(start.camera_id) ||
        !reconstruction_.ExistsCamera(start.camera_id)) {
      continue;
    }
    Camera& camera = reconstruction_.GetCamera(start.camera_id);
    if (!adjuster.problem().HasParameterBlock(camera.params.data())) continue;
    adjuster.problem().AddResidualBlock(
        new FocalPriorCost(static_cast<int>(camera.params.size()), start.MeanFocalLength(),
                           options_.focal_prior_sigma_log),
        nullptr, camera.params.data());
  }
}

image_t MapperState::ScaleGaugeImage() const {
  // block.mp4's bundle after its loop closing, gauged by two consecutive frames at the loop's
  // seam, grew the model about 7x in 100 iterations; the farthest frame holds it.
  return FarthestRegisteredImage(reconstruction_, gauge1_, gauge2_);
}

void MapperState::GlobalRefinement(MapperReport* report,
                                   std::optional<double> settle_tolerance) {
  const GlobalBundleScope scope{.settle_tolerance = settle_tolerance};
  GlobalBundle(report, scope);
  Timer tri_timer;
  const size_t added = RetriangulateAll();
  const size_t removed = FilterPoints({});
  report->seconds_triangulation += tri_timer.ElapsedSeconds();
  const size_t observations = reconstruction_.ComputeNumObservations();
  spdlog::debug("global refinement: {} observations added and {} removed after the bundle, "
                "of {}", added, removed, observations);
  if (added + removed > 0.02 * observations) {
    GlobalBundle(report, scope);
    tri_timer.Restart();
    FilterPoints({});
    report->seconds_triangulation += tri_timer.ElapsedSeconds();
  }
}

void MapperState::WindowRefinement(const std::vector<image_t>& frames, MapperReport* report) {
  const GlobalBundleScope scope{.frames = frames};
  GlobalBundle(report, scope);
  Timer tri_timer;
  const size_t added = RetriangulateFrames(frames);
  const size_t removed = FilterPoints(PointsSeenBy(reconstruction_, frames));
  size_t observations = 0;
  const std::vector<point3D_t> points = PointsSeenBy(reconstruction_, frames, &observations);
  report->seconds_triangulation += tri_timer.ElapsedSeconds();
  if (added + removed > 0.02 * observations) {
    GlobalBundle(report, scope);
    tri_timer.Restart();
    FilterPoints(points);
    report->seconds_triangulation += tri_timer.ElapsedSeconds();
  }
}

void MapperState::RefineAfterCorrection(MapperReport* report,
                                        std::optional<double> subset_function_tolerance) {
  const LoopClosureOptions& loop = options_.loop_closure;
  if (loop.refine_points_per_frame > 0) {
    SubsetBundle(report, loop.refine_points_per_frame, {}, {}, subset_function_tolerance);
    GlobalRefinement(report, loop.polish_settle_tolerance);
  } else {
    GlobalRefinement(report);
  }
}

void MapperState::SubsetBundle(MapperReport* report, int per_frame,
                               const std::function<void(BundleAdjuster&)>& add_terms,
                               const std::vector<point3D_t>& also,
                               std::optional<double> function_tolerance) {
  std::unordered_set<point3D_t> subset = LongestTrackPoints(per_frame);
  subset.insert(also.begin(), also.end());
  std::vector<point3D_t> others;
  for (const auto& [id, point] : reconstruction_.Points3D()) {
    if (subset.count(id) == 0) others.push_back(id);
  }
  GlobalBundle(report, {.add_terms = add_terms,
                        .points = std::move(subset),
                        .function_tolerance = function_tolerance});
  Timer tri_timer;
  RepositionPoints(others);
  // Some points no longer fit the moved cameras (observations far off, or seen under too
  // small an angle now). Left in, they lengthen the full bundle's steps and spoil its linear
  // model: on drift2 (focal -5 %) its steps were up to 3e5 long and 10 of 32 were rejected;
  // without them (1.7 % of the observations), at most 55 long, 13 steps, none rejected.
  FilterPoints(others);
  report->seconds_triangulation += tri_timer.ElapsedSeconds();
}

std::unordered_set<point3D_t> MapperState::LongestTrackPoints(int per_frame) const {
  // Long tracks of distant points see them under a small angle: their depth is barely
  // constrained, and a bundle of few points with many of them is ill-conditioned (Cholesky
  // failures, cameras left off). Only points seen under twice the triangulation angle (its
  // widest from the first observer) are taken.
  const double min_angle = 2.0 * options_.min_tri_angle_deg * M_PI / 180.0;
  std::vector<std::pair<size_t, point3D_t>> by_length;  // (track length, id)
  for (const auto& [id, point] : reconstruction_.Points3D()) {
    const auto& elements = point.track.elements;
    const Eigen::Vector3d first = reconstruction_.GetImage(elements[0].image_id).ProjectionCenter();
    double widest = 0.0;
    for (size_t k = 1; k < elements.size() && widest < min_angle; ++k) {
      const Image& other = reconstruction_.GetImage(elements[k].image_id);
      widest = std::max(widest,
                        CalculateTriangulationAngle(first, other.ProjectionCenter(), point.xyz));
    }
    if (widest < min_angle) continue;
    by_length.push_back({elements.size(), id});
  }
  std::sort(by_length.begin(), by_length.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  std::unordered_map<image_t, int> taken;
  std::unordered_set<point3D_t> subset;
  for (const auto& [length, id] : by_length) {
    const auto& elements = reconstruction_.GetPoint3D(id).track.elements;
    const bool wanted = std::any_of(elements.begin(), elements.end(), [&](const TrackElement& el) {
      return taken[el.image_id] < per_frame;
    });
    if (!wanted) continue;
    subset.insert(id);
    for (const TrackElement& el : elements) ++taken[el.image_id];
  }
  return subset;
}

}  // namespace loopsfm
