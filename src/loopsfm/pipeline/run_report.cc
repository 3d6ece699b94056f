#include "loopsfm/pipeline/run_report.h"

#include <chrono>
#include <map>
#include <string>
#include <vector>

#include <fmt/chrono.h>
#include <fmt/format.h>

#include "loopsfm/eval/trajectory_metrics.h"
#include "loopsfm/report/report_data.h"
#include "loopsfm/report/top_view.h"

namespace loopsfm {
namespace fs = std::filesystem;
namespace {

std::vector<Eigen::Vector3d> Centres(const std::vector<TrajectoryEntry>& path) {
  std::vector<Eigen::Vector3d> centres;
  for (const TrajectoryEntry& e : path) centres.push_back(e.world_from_cam.translation);
  return centres;
}

// Centres of `path` aligned to the ground truth (a similarity of its own), in ground-truth
// order; empty when it cannot be aligned.
std::vector<Eigen::Vector3d> AlignedCentres(const TrajectoryMetrics& metrics) {
  std::vector<Eigen::Vector3d> centres;
  if (!metrics.aligned) return centres;
  for (const FrameError& f : metrics.frames) centres.push_back(f.aligned_centre);
  return centres;
}

nlohmann::json TopView(const std::vector<TrajectoryEntry>& path,
                       const std::vector<TrajectoryEntry>& before,
                       const std::vector<LoopLink>& links,
                       const std::optional<std::vector<TrajectoryEntry>>& groundtruth,
                       nlohmann::json* evaluation) {
  std::vector<std::pair<std::string, std::vector<Eigen::Vector3d>>> paths;
  std::map<std::string, Eigen::Vector3d> drawn;  // frame name -> centre as drawn
  if (groundtruth) {
    const TrajectoryMetrics metrics = EvaluateTrajectory(path, *groundtruth);
    paths.push_back({"ground truth", Centres(*groundtruth)});
    paths.push_back({"loopsfm", AlignedCentres(metrics)});
    if (metrics.aligned) {
      for (const FrameError& f : metrics.frames) drawn[f.estimated_name] = f.aligned_centre;
    }
    if (!before.empty()) {
      paths.push_back({"before loop closing", AlignedCentres(EvaluateTrajectory(before, *groundtruth))});
    }
    if (metrics.aligned) {
      *evaluation = {{"ate_fraction_of_path", metrics.ate_fraction_of_path},
                     {"ate_rmse", metrics.ate_rmse},
                     {"rotation_error_mean_deg", metrics.rotation_error_mean_deg}};
      if (metrics.loop_gaps && metrics.loop_gaps->num_revisits > 0) {
        (*evaluation)["loop_gap_max"] = metrics.loop_gaps->max;
        (*evaluation)["loop_gap_mean"] = metrics.loop_gaps->mean;
      }
    } else {
      *evaluation = {{"explanation", metrics.explanation}};
    }
  } else {
    paths.push_back({"loopsfm", Centres(path)});
    if (!before.empty()) paths.push_back({"before loop closing", Centres(before)});
    for (const TrajectoryEntry& e : path) drawn[e.name] = e.world_from_cam.translation;
  }
  if (paths[0].second.empty()) return nullptr;
  const TopViewPlane plane = FitTopViewPlane(paths[0].second);
  nlohmann::json view = {{"x_label", "first principal axis"},
                         {"y_label", "second principal axis"},
                         {"paths", nlohmann::json::array()}};
  for (const auto& [label, centres] : paths) {
    if (!centres.empty()) view["paths"].push_back(ReportTopViewPath(label, centres, plane));
  }
  view["links"] = ReportTopViewLinks(links, drawn, plane);
  return view;
}

// The global mapper's warnings about its models, as the log gave them, for the summary.
std::vector<std::string> GlobalMapperWarnings(const ReconstructReport& report) {
  std::vector<std::string> warnings;
  if (report.segments) {
    const std::vector<SegmentReport>& segments = report.segments->segments;
    for (size_t k = 0; k < segments.size(); ++k) {
      if (!segments[k].global_set_aside) continue;
      warnings.push_back(fmt::format(
          "segment {} (frames {}-{}): the global mapper found its path likely bent or broken "
          "(see the log), so the incremental mapper mapped it instead",
          k, segments[k].first_frame, segments[k].first_frame + segments[k].num_frames - 1));
    }
  }
  if (!report.global_mapper) return warnings;
  const GlobalMapperReport& g = *report.global_mapper;
  // Where the pipeline took the advice already, what it did instead.
  const std::string advice = report.global_mapper_set_aside
                                 ? "so the incremental mapper mapped the video instead, "
                                   "and its model is the one shown"
                                 : "map with --mapper incremental";
  if (g.num_bent_components > 0) {
    warnings.push_back(fmt::format(
        "{} component{} likely bent: global positioning left many observations off (the "
        "largest component: {:.1f} % more than {:.0f} deg), as the wrong matches of repeated "
        "structure do; {}",
        g.num_bent_components, g.num_bent_components == 1 ? "" : "s",
        100.0 * g.positioning.LargeAngleFraction(),
        GlobalPositioningOptions().max_angle_error_deg, advice));
  }
  if (g.num_broken_models > 0) {
    warnings.push_back(fmt::format(
        "{} model{} likely broken: a path jumps (model 0's largest step {:.0f}x the median, {} "
        "to {}); {}",
        g.num_broken_models, g.num_broken_models == 1 ? "" : "s", g.largest_step_ratio,
        g.largest_step_from, g.largest_step_to, advice));
  }
  return warnings;
}

}  // namespace

nlohmann::json RunReportData(const ReconstructReport& report,
                             const std::vector<Reconstruction>& models,
                             const std::vector<Frame>& frames, const fs::path& input,
                             const fs::path& output_dir,
                             const std::optional<std::vector<TrajectoryEntry>>& groundtruth) {
  nlohmann::json data;
  data["title"] = fmt::format("loopsfm: {}", input.filename().string());
  data["input"] = fs::absolute(input).lexically_normal().string();
  data["output"] = fs::absolute(output_dir).lexically_normal().string();
  data["created"] = fmt::format("{:%Y-%m-%dT%H:%M:%SZ}", fmt::gmtime(std::time(nullptr)));
  size_t registered = 0;
  for (const Reconstruction& model : models) registered += model.NumRegImages();
  const bool global = report.global_mapper || (report.segments && report.segments->global);
  std::string mapper = !global                          ? "incremental"
                       : report.global_mapper_set_aside ? "incremental (instead of the global "
                                                          "mapper, see the warnings)"
                                                        : "global";
  if (report.segments) mapper += fmt::format(", {} segments", report.segments->segments.size());
  data["summary"] = {{"frames", report.num_frames},
                     {"mapper", mapper},
                     {"registered", registered},
                     {"models", models.size()},
                     {"total_seconds", report.total_seconds},
                     {"peak_memory_mib", report.peak_memory_bytes / 1048576.0}};
  const std::vector<std::string> warnings = GlobalMapperWarnings(report);
  if (!warnings.empty()) data["summary"]["warnings"] = warnings;
  if (!report.output.models.empty()) {
    const ModelSummary& first = report.output.models[0];
    data["summary"]["points"] = first.num_points;
    data["summary"]["mean_track_length"] = first.mean_track_length;
    data["summary"]["reprojection_error_px"] = first.mean_reprojection_error;
  }
  data["stages"] = nlohmann::json::array();
  for (const StageTime& t : report.stage_times) {
    data["stages"].push_back({{"name", t.stage}, {"seconds", t.seconds}});
  }
  data["frames"] = ReportFrames(frames, models);
  // The alternate pose diagnostic: the last registration of each frame, both rounds.
  std::map<std::string, const RegistrationRounds*> rounds;
  for (const RegistrationRounds& r : report.mapper.registrations) rounds[r.frame] = &r;
  for (nlohmann::json& frame : data["frames"]) {
    const auto it = rounds.find(frame["name"].get<std::string>());
    if (it == rounds.end()) continue;
    const RegistrationRounds& r = *it->second;
    frame["registration_inlier_ratio"] = static_cast<double>(r.num_inliers) / r.num_correspondences;
    if (r.second_num_correspondences > 0) {
      frame["alternate_inlier_ratio"] =
          static_cast<double>(r.second_num_inliers) / r.second_num_correspondences;
      frame["alternate_pose"] = r.second_pose_found;
    }
  }
  data["matrices"] = nlohmann::json::array();
  for (const auto& [title, file] :
       {std::pair{"Similarity (vocabulary tree)", "database_similarity.png"},
        std::pair{"Verified matches", "database_matches.png"}}) {
    if (fs::exists(output_dir / file)) data["matrices"].push_back(ReportImage(title, output_dir / file));
  }
  data["loops"] = nlohmann::json::array();
  for (const ClosedLoop& loop : report.mapper.loops_closed) {
    data["loops"].push_back({{"recent_frame", loop.recent_frame},
                             {"old_frame", loop.old_frame},
                             {"num_inliers", loop.num_inliers},
                             {"num_correspondences", loop.num_correspondences},
                             {"correction_translation", loop.correction_translation},
                             {"correction_rotation_deg", loop.correction_rotation_deg},
                             {"correction_scale", loop.correction_scale},
                             {"seconds", loop.seconds}});
  }
  // Every frame of the source, as index lists rather than an object per frame: a video
  // has tens of thousands.
  const FrameTimeline& timeline = report.timeline;
  if (timeline.frames_read > 0) {
    nlohmann::json kept = nlohmann::json::array();
    for (const auto& [index, reason] : timeline.kept) {
      kept.push_back(nlohmann::json::array({index, reason}));
    }
    data["timeline"] = {{"frames_read", timeline.frames_read},
                        {"kept", std::move(kept)},
                        {"blurred", timeline.blurred},
                        {"localized", timeline.localized}};
  }
  if (models.empty()) return data;
  data["cameras"] = ReportCameras(models[0]);
  data["points"] = ReportPoints(models[0]);
  nlohmann::json evaluation;
  data["top_view"] = TopView(TrajectoryFromReconstruction(models[0]),
                             report.mapper.path_before_loop_closing, report.mapper.loop_links,
                             groundtruth, &evaluation);
  if (!evaluation.is_null()) data["evaluation"] = evaluation;
  return data;
}

}  // namespace loopsfm
