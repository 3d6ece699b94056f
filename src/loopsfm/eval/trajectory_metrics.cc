#include "loopsfm/eval/trajectory_metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

#include <Eigen/Eigenvalues>

#include "loopsfm/geometry/umeyama.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double Median(std::vector<double> values) {
  if (values.empty()) return kNaN;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  const double upper = values[mid];
  if (values.size() % 2 == 1) return upper;
  const double lower = *std::max_element(values.begin(), values.begin() + mid);
  return 0.5 * (lower + upper);
}

double Mean(const std::vector<double>& values) {
  if (values.empty()) return kNaN;
  double sum = 0.0;
  for (double v : values) sum += v;
  return sum / static_cast<double>(values.size());
}

double Rms(const std::vector<double>& values) {
  if (values.empty()) return kNaN;
  double sum = 0.0;
  for (double v : values) sum += v * v;
  return std::sqrt(sum / static_cast<double>(values.size()));
}

double Max(const std::vector<double>& values) {
  return values.empty() ? kNaN : *std::max_element(values.begin(), values.end());
}

// world_from_cam of an estimated frame mapped into the ground-truth world by the
// similarity: the centre moves with the full Sim3, the orientation with its rotation.
Rigid3d AlignPose(const Sim3d& gt_from_est, const Rigid3d& world_from_cam) {
  return Rigid3d((gt_from_est.rotation * world_from_cam.rotation).normalized(),
                 gt_from_est * world_from_cam.translation);
}

void SetErrorsToNaN(TrajectoryMetrics* m) {
  m->ate_rmse = m->ate_mean = m->ate_median = m->ate_max = m->ate_fraction_of_path = kNaN;
  m->rotation_error_mean_deg = m->rotation_error_median_deg = m->rotation_error_max_deg = kNaN;
  m->alignment_roll_uncertainty_deg = kNaN;
}

// Standard error (degrees) of the alignment's rotation about the main axis of `centres`
// (ground truth), given the aligned centres' `errors`: a roll by theta moves a centre at
// distance r from the axis by about r * theta, across the axis, so the least-squares roll
// has the standard error rms(errors across the axis) / sqrt(sum of r^2).
double RollUncertaintyDegrees(const std::vector<Eigen::Vector3d>& centres,
                              const std::vector<Eigen::Vector3d>& errors) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& c : centres) mean += c;
  mean /= static_cast<double>(centres.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& c : centres) scatter += (c - mean) * (c - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);
  const Eigen::Vector3d axis = eigen.eigenvectors().col(2);  // largest eigenvalue
  // The scatter off the axis: the centres' squared distances from it, summed.
  const double off_axis = eigen.eigenvalues()(0) + eigen.eigenvalues()(1);
  double across = 0.0;
  for (const Eigen::Vector3d& e : errors) across += (e - e.dot(axis) * axis).squaredNorm();
  if (!(off_axis > 0.0)) return kNaN;
  return std::atan(std::sqrt(across / errors.size() / off_axis)) * 180.0 / M_PI;
}

RelativePoseErrors ComputeRpe(const std::vector<TrajectoryEntry>& ground_truth,
                              const std::vector<Rigid3d>& aligned_by_gt_index,
                              const std::vector<bool>& matched_by_gt_index, int step) {
  RelativePoseErrors rpe;
  rpe.step = step;
  std::vector<double> translation_errors, rotation_errors;
  for (size_t k = 0; k + step < ground_truth.size(); ++k) {
    if (!matched_by_gt_index[k] || !matched_by_gt_index[k + step]) continue;
    const Rigid3d gt_rel =
        ground_truth[k].world_from_cam.Inverse() * ground_truth[k + step].world_from_cam;
    const Rigid3d est_rel = aligned_by_gt_index[k].Inverse() * aligned_by_gt_index[k + step];
    const Rigid3d error = gt_rel.Inverse() * est_rel;
    translation_errors.push_back(error.translation.norm());
    rotation_errors.push_back(RotationAngleDegrees(error.rotation));
  }
  rpe.num_pairs = translation_errors.size();
  rpe.translation_rmse = Rms(translation_errors);
  rpe.translation_mean = Mean(translation_errors);
  rpe.translation_max = Max(translation_errors);
  rpe.rotation_mean_deg = Mean(rotation_errors);
  rpe.rotation_max_deg = Max(rotation_errors);
  return rpe;
}

LoopGaps ComputeLoopGaps(const std::vector<TrajectoryEntry>& ground_truth,
                         const std::vector<Rigid3d>& aligned_by_gt_index,
                         const std::vector<bool>& matched_by_gt_index,
                         const TrajectoryEvalOptions& options) {
  const size_t n = ground_truth.size();
  auto gt_centre = [&](size_t k) -> const Eigen::Vector3d& {
    return ground_truth[k].world_from_cam.translation;
  };
  LoopGaps gaps;
  gaps.min_frame_gap = options.loop_min_frame_gap > 0
                           ? options.loop_min_frame_gap
                           : std::max(10, static_cast<int>(n / 5));
  std::vector<double> steps;
  for (size_t k = 1; k < n; ++k) steps.push_back((gt_centre(k) - gt_centre(k - 1)).norm());
  gaps.max_distance = steps.empty() ? 0.0 : options.loop_max_distance_steps * Median(steps);
  gaps.mean = gaps.median = gaps.max = kNaN;
  if (!(gaps.max_distance > 0.0)) return gaps;

  auto viewing_direction = [&](size_t k) -> Eigen::Vector3d {
    return ground_truth[k].world_from_cam.rotation * Eigen::Vector3d::UnitZ();
  };
  const double min_cos_view = std::cos(options.loop_max_view_angle_deg * M_PI / 180.0);
  std::vector<double> values;
  for (size_t i = 0; i < n; ++i) {
    if (!matched_by_gt_index[i]) continue;
    size_t best = n;
    double best_distance = gaps.max_distance;
    for (size_t j = i + gaps.min_frame_gap; j < n; ++j) {
      if (!matched_by_gt_index[j]) continue;
      if (viewing_direction(i).dot(viewing_direction(j)) < min_cos_view) continue;
      const double distance = (gt_centre(j) - gt_centre(i)).norm();
      if (distance <= best_distance) {
        best_distance = distance;
        best = j;
      }
    }
    if (best == n) continue;
    const Eigen::Vector3d estimated_offset =
        aligned_by_gt_index[best].translation - aligned_by_gt_index[i].translation;
    const double gap = (estimated_offset - (gt_centre(best) - gt_centre(i))).norm();
    if (values.empty() || gap > gaps.max) {
      gaps.max = gap;
      gaps.max_first = ground_truth[i].name;
      gaps.max_second = ground_truth[best].name;
    }
    values.push_back(gap);
  }
  gaps.num_revisits = values.size();
  gaps.mean = Mean(values);
  gaps.median = Median(values);
  return gaps;
}

// null for NaN / infinity, so the JSON stays valid for every reader.
nlohmann::json Number(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

}  // namespace

void TrajectoryEvalOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(rpe_step >= 0, "rpe_step must be >= 0 (0 disables RPE), got {}", rpe_step);
  LOOPSFM_REQUIRE_OPTION(min_matched_frames >= 3,
                         "min_matched_frames must be >= 3 (a similarity needs 3 points), got {}",
                         min_matched_frames);
  LOOPSFM_REQUIRE_OPTION(loop_min_frame_gap >= 0,
                         "loop_min_frame_gap must be >= 0 (0: automatic), got {}",
                         loop_min_frame_gap);
  LOOPSFM_REQUIRE_OPTION(loop_max_distance_steps > 0.0,
                         "loop_max_distance_steps must be > 0, got {}", loop_max_distance_steps);
  LOOPSFM_REQUIRE_OPTION(loop_max_view_angle_deg > 0.0 && loop_max_view_angle_deg <= 180.0,
                         "loop_max_view_angle_deg must be in (0, 180], got {}",
                         loop_max_view_angle_deg);
}

std::string TrajectoryNameKey(const std::string& name) {
  size_t begin = name.find_last_of("/\\");
  begin = begin == std::string::npos ? 0 : begin + 1;
  const size_t dot = name.find_last_of('.');
  // A leading dot (".hidden") is part of the name, not an extension.
  const size_t end = (dot == std::string::npos || dot <= begin) ? name.size() : dot;
  return name.substr(begin, end - begin);
}

std::vector<FrameMatch> JoinTrajectoriesByName(const std::vector<TrajectoryEntry>& estimated,
                                               const std::vector<TrajectoryEntry>& ground_truth,
                                               bool match_without_extension) {
  std::unordered_map<std::string, std::vector<size_t>> estimated_by_name;
  for (size_t i = 0; i < estimated.size(); ++i) estimated_by_name[estimated[i].name].push_back(i);
  std::vector<bool> estimated_used(estimated.size(), false);
  std::vector<bool> gt_matched(ground_truth.size(), false);
  std::vector<FrameMatch> matches;

  for (size_t g = 0; g < ground_truth.size(); ++g) {
    const auto it = estimated_by_name.find(ground_truth[g].name);
    if (it == estimated_by_name.end()) continue;
    for (size_t e : it->second) {
      if (estimated_used[e]) continue;
      estimated_used[e] = true;
      gt_matched[g] = true;
      matches.push_back({g, e});
      break;
    }
  }

  if (match_without_extension) {
    std::unordered_map<std::string, std::vector<size_t>> estimated_by_key;
    std::unordered_map<std::string, int> gt_key_count;
    for (size_t i = 0; i < estimated.size(); ++i) {
      estimated_by_key[TrajectoryNameKey(estimated[i].name)].push_back(i);
    }
    for (const auto& entry : ground_truth) ++gt_key_count[TrajectoryNameKey(entry.name)];
    for (size_t g = 0; g < ground_truth.size(); ++g) {
      if (gt_matched[g]) continue;
      const std::string key = TrajectoryNameKey(ground_truth[g].name);
      const auto it = estimated_by_key.find(key);
      if (it == estimated_by_key.end() || it->second.size() != 1 || gt_key_count[key] != 1) {
        continue;
      }
      const size_t e = it->second.front();
      if (estimated_used[e]) continue;
      estimated_used[e] = true;
      gt_matched[g] = true;
      matches.push_back({g, e});
    }
  }

  std::sort(matches.begin(), matches.end(),
            [](const FrameMatch& a, const FrameMatch& b) { return a.gt_index < b.gt_index; });
  return matches;
}

std::vector<TrajectoryEntry> TrajectoryFromReconstruction(const Reconstruction& reconstruction) {
  std::vector<TrajectoryEntry> entries;
  for (const auto& [image_id, image] : reconstruction.Images()) {
    if (!image.registered) continue;
    entries.push_back({image.name, image.cam_from_world.Inverse()});
  }
  std::sort(entries.begin(), entries.end(),
            [](const TrajectoryEntry& a, const TrajectoryEntry& b) { return a.name < b.name; });
  return entries;
}

double TrajectoryPathLength(const std::vector<TrajectoryEntry>& trajectory) {
  double length = 0.0;
  for (size_t i = 1; i < trajectory.size(); ++i) {
    length +=
        (trajectory[i].world_from_cam.translation - trajectory[i - 1].world_from_cam.translation)
            .norm();
  }
  return length;
}

TrajectoryMetrics EvaluateTrajectory(const std::vector<TrajectoryEntry>& estimated,
                                     const std::vector<TrajectoryEntry>& ground_truth,
                                     const TrajectoryEvalOptions& options) {
  options.Check();
  TrajectoryMetrics metrics;
  metrics.num_gt_frames = ground_truth.size();
  metrics.num_estimated = estimated.size();
  metrics.gt_path_length = TrajectoryPathLength(ground_truth);
  SetErrorsToNaN(&metrics);

  const std::vector<FrameMatch> matches =
      JoinTrajectoriesByName(estimated, ground_truth, options.match_without_extension);
  metrics.num_matched = matches.size();
  metrics.fraction_registered =
      ground_truth.empty() ? 0.0 : static_cast<double>(matches.size()) / ground_truth.size();
  for (const FrameMatch& match : matches) {
    FrameError frame;
    frame.gt_name = ground_truth[match.gt_index].name;
    frame.estimated_name = estimated[match.estimated_index].name;
    frame.gt_index = match.gt_index;
    frame.position_error = kNaN;
    frame.rotation_error_deg = kNaN;
    metrics.frames.push_back(std::move(frame));
  }

  if (matches.size() < static_cast<size_t>(options.min_matched_frames)) {
    std::string example;
    if (!ground_truth.empty() && !estimated.empty()) {
      example = fmt::format(" (e.g. ground truth '{}', estimate '{}')", ground_truth.front().name,
                            estimated.front().name);
    }
    metrics.explanation = fmt::format(
        "only {} of {} estimated frames match the {} ground-truth frames by name, {} are needed "
        "to align the trajectories; check that the frame names agree{}",
        matches.size(), estimated.size(), ground_truth.size(), options.min_matched_frames, example);
    return metrics;
  }

  std::vector<Eigen::Vector3d> estimated_centres, gt_centres;
  for (const FrameMatch& match : matches) {
    estimated_centres.push_back(estimated[match.estimated_index].world_from_cam.translation);
    gt_centres.push_back(ground_truth[match.gt_index].world_from_cam.translation);
  }
  const std::optional<Sim3d> gt_from_est = EstimateSim3(estimated_centres, gt_centres);
  if (!gt_from_est) {
    metrics.explanation = fmt::format(
        "the {} matched camera centres do not determine a similarity transform (they are "
        "coincident or on one line in the estimate or the ground truth)",
        matches.size());
    return metrics;
  }
  metrics.aligned = true;
  metrics.gt_from_estimated = *gt_from_est;

  std::vector<double> position_errors, rotation_errors;
  std::vector<Eigen::Vector3d> centre_errors;
  std::vector<Rigid3d> aligned_by_gt_index(ground_truth.size());
  std::vector<bool> matched_by_gt_index(ground_truth.size(), false);
  for (size_t i = 0; i < matches.size(); ++i) {
    const Rigid3d& gt = ground_truth[matches[i].gt_index].world_from_cam;
    const Rigid3d aligned =
        AlignPose(*gt_from_est, estimated[matches[i].estimated_index].world_from_cam);
    FrameError& frame = metrics.frames[i];
    frame.aligned_centre = aligned.translation;
    frame.position_error = (aligned.translation - gt.translation).norm();
    frame.rotation_error_deg = RotationAngleDegrees(gt.rotation.inverse() * aligned.rotation);
    position_errors.push_back(frame.position_error);
    centre_errors.push_back(aligned.translation - gt.translation);
    rotation_errors.push_back(frame.rotation_error_deg);
    aligned_by_gt_index[matches[i].gt_index] = aligned;
    matched_by_gt_index[matches[i].gt_index] = true;
  }
  metrics.ate_rmse = Rms(position_errors);
  metrics.ate_mean = Mean(position_errors);
  metrics.ate_median = Median(position_errors);
  metrics.ate_max = Max(position_errors);
  metrics.ate_fraction_of_path =
      metrics.gt_path_length > 0.0 ? metrics.ate_rmse / metrics.gt_path_length : kNaN;
  metrics.rotation_error_mean_deg = Mean(rotation_errors);
  metrics.rotation_error_median_deg = Median(rotation_errors);
  metrics.rotation_error_max_deg = Max(rotation_errors);
  metrics.alignment_roll_uncertainty_deg = RollUncertaintyDegrees(gt_centres, centre_errors);
  if (options.rpe_step > 0) {
    metrics.rpe =
        ComputeRpe(ground_truth, aligned_by_gt_index, matched_by_gt_index, options.rpe_step);
  }
  metrics.loop_gaps =
      ComputeLoopGaps(ground_truth, aligned_by_gt_index, matched_by_gt_index, options);
  return metrics;
}

TrajectoryMetrics EvaluateTrajectory(const Reconstruction& reconstruction,
                                     const std::vector<TrajectoryEntry>& ground_truth,
                                     const TrajectoryEvalOptions& options) {
  return EvaluateTrajectory(TrajectoryFromReconstruction(reconstruction), ground_truth, options);
}

nlohmann::json ToJson(const TrajectoryMetrics& m, bool include_frames) {
  nlohmann::json json;
  json["num_gt_frames"] = m.num_gt_frames;
  json["num_estimated"] = m.num_estimated;
  json["num_matched"] = m.num_matched;
  json["fraction_registered"] = Number(m.fraction_registered);
  json["gt_path_length"] = Number(m.gt_path_length);
  json["aligned"] = m.aligned;
  json["explanation"] = m.explanation;
  if (m.aligned) {
    const Sim3d& sim = m.gt_from_estimated;
    json["gt_from_estimated"] = {
        {"scale", sim.scale},
        {"rotation_wxyz", {sim.rotation.w(), sim.rotation.x(), sim.rotation.y(), sim.rotation.z()}},
        {"translation", {sim.translation.x(), sim.translation.y(), sim.translation.z()}}};
  } else {
    json["gt_from_estimated"] = nullptr;
  }
  json["ate_rmse"] = Number(m.ate_rmse);
  json["ate_mean"] = Number(m.ate_mean);
  json["ate_median"] = Number(m.ate_median);
  json["ate_max"] = Number(m.ate_max);
  json["ate_fraction_of_path"] = Number(m.ate_fraction_of_path);
  json["rotation_error_mean_deg"] = Number(m.rotation_error_mean_deg);
  json["rotation_error_median_deg"] = Number(m.rotation_error_median_deg);
  json["rotation_error_max_deg"] = Number(m.rotation_error_max_deg);
  json["alignment_roll_uncertainty_deg"] = Number(m.alignment_roll_uncertainty_deg);
  if (m.rpe) {
    json["rpe"] = {{"step", m.rpe->step},
                   {"num_pairs", m.rpe->num_pairs},
                   {"translation_rmse", Number(m.rpe->translation_rmse)},
                   {"translation_mean", Number(m.rpe->translation_mean)},
                   {"translation_max", Number(m.rpe->translation_max)},
                   {"rotation_mean_deg", Number(m.rpe->rotation_mean_deg)},
                   {"rotation_max_deg", Number(m.rpe->rotation_max_deg)}};
  } else {
    json["rpe"] = nullptr;
  }
  if (m.loop_gaps) {
    const LoopGaps& g = *m.loop_gaps;
    json["loop_gaps"] = {{"min_frame_gap", g.min_frame_gap},
                         {"max_distance", Number(g.max_distance)},
                         {"num_revisits", g.num_revisits},
                         {"mean", Number(g.mean)},
                         {"median", Number(g.median)},
                         {"max", Number(g.max)},
                         {"max_first", g.max_first},
                         {"max_second", g.max_second}};
  } else {
    json["loop_gaps"] = nullptr;
  }
  if (include_frames) {
    json["frames"] = nlohmann::json::array();
    for (const FrameError& f : m.frames) {
      json["frames"].push_back({{"gt_name", f.gt_name},
                                {"estimated_name", f.estimated_name},
                                {"gt_index", f.gt_index},
                                {"position_error", Number(f.position_error)},
                                {"rotation_error_deg", Number(f.rotation_error_deg)},
                                {"aligned_centre",
                                 {Number(f.aligned_centre.x()), Number(f.aligned_centre.y()),
                                  Number(f.aligned_centre.z())}}});
    }
  }
  return json;
}

}  // namespace loopsfm
