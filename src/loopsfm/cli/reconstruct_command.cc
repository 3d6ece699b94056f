#include <algorithm>
#include <map>

#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/cli/map_flags.h"
#include "loopsfm/cli/stage_flags.h"
#include "loopsfm/math/random.h"
#include "loopsfm/pipeline/reconstruct.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm::cli {
namespace {

std::string IncrementalMapperSummary(const MapperReport& m);
std::string GlobalMapperSummary(const GlobalMapperReport& g, const MapperReport& m);
std::string SegmentSummary(const SegmentMappingReport& s);

std::string SummaryText(const ReconstructReport& report) {
  std::string out = "\n";
  out += fmt::format("{:<28}{}\n", "frames", report.num_frames);
  const ExtractReport& e = report.extract;
  if (e.frames_read > 0 && e.frames_read != e.frames_decoded) {
    out += fmt::format("{:<28}{} of {} read ({} judged blurred); {} in-between added\n",
                       "keyframes", e.frames_decoded, e.frames_read, e.frames_blurred,
                       report.fill_in_frames);
  }
  if (report.localize.frames_read > 0) {
    out += fmt::format("{:<28}{} of {} between keyframes\n", "localised frames",
                       report.localize.localized,
                       report.localize.localized + report.localize.not_localized);
  }
  for (size_t m = 0; m < report.output.models.size(); ++m) {
    const ModelSummary& s = report.output.models[m];
    out += fmt::format("{:<28} {} registered, {} points, track length {:.2f}, reprojection "
                       "error {:.3f} px\n",
                       fmt::format("model {} ({})", m, s.path.string()), s.num_registered,
                       s.num_points, s.mean_track_length, s.mean_reprojection_error);
  }
  if (report.output.models.empty()) out += fmt::format("{:<28}{}\n", "models", "none");
  if (!report.output.written.empty()) {
    std::string written;
    for (const auto& path : report.output.written) {
      written += (written.empty() ? "" : ", ") + path.filename().string();
    }
    out += fmt::format("{:<28}{} ({})\n", "written", written, report.output.Counts());
  }
  for (const CameraSelfCalibration& c : report.self_calibration.cameras) {
    out += fmt::format("{:<28}", fmt::format("self-calibration camera {}", c.camera_id));
    if (c.applied) {
      out += fmt::format("focal {:.1f} px, spread {:.2f} %, {} of {} pairs agree", c.focal_px,
                         100.0 * c.estimate.spread, c.estimate.num_pairs_inlier,
                         c.estimate.num_pairs);
      if (c.distortion.significant) {
        out += fmt::format(", k1 {:.4f} (epipolar error {:.2f} px, {:.2f} px without)", c.k1,
                           c.distortion.error_px, c.distortion.error_px_without);
      } else if (c.distortion_estimated) {
        out += ", no distortion found";
      }
      out += "\n";
    } else {
      out += fmt::format("kept the guess {:.1f} px: {}\n", c.initial_focal_px,
                         c.estimate.explanation);
    }
  }
  if (!report.output.models.empty()) {
    for (const Camera& camera : report.output.models[0].cameras) {
      std::string params;
      for (double p : camera.params) params += fmt::format(" {:.6g}", p);
      out += fmt::format("{:<28}{} {}x{}{}\n", fmt::format("model 0 camera {}", camera.camera_id),
                         camera.ModelName(), camera.width, camera.height, params);
    }
  }
  for (const StageTime& t : report.stage_times) {
    out += fmt::format("{:<28}{:.1f} s\n", "time " + t.stage, t.seconds);
  }
  if (report.global_mapper) {
    out += GlobalMapperSummary(*report.global_mapper,
                               report.global_mapper_set_aside.value_or(report.mapper));
  }
  if (report.global_mapper_set_aside) {
    out += fmt::format("{:<28}the global mapper's path likely {}: the incremental mapper's "
                       "model replaces it\n",
                       "incremental mapper", report.global_mapper->Fault());
  }
  if (!report.global_mapper || report.global_mapper_set_aside) {
    out += IncrementalMapperSummary(report.mapper);
  }
  if (report.segments) out += SegmentSummary(*report.segments);
  out += fmt::format("{:<28}{:.1f} s, peak memory {:.0f} MiB\n", "total", report.total_seconds,
                     report.peak_memory_bytes / 1048576.0);
  return out;
}

std::string IncrementalMapperSummary(const MapperReport& m) {
  std::string out;
  out += fmt::format("{:<28}registration {:.1f} s, triangulation {:.1f} s, {} local BA {:.1f} s, "
                     "{} global BA {:.1f} s, merging {:.1f} s, checkpoints {:.1f} s\n",
                     "  of which", m.seconds_registration, m.seconds_triangulation, m.num_local_ba,
                     m.seconds_local_ba, m.num_global_ba, m.seconds_global_ba, m.seconds_merging,
                     m.seconds_checkpoints);
  auto per = [](long long total, int count) { return count > 0 ? double(total) / count : 0.0; };
  out += fmt::format("{:<28}local BA {:.1f} iterations, {:.0f} residuals; global BA {:.1f} "
                     "iterations, {:.0f} residuals (means)\n",
                     "  bundles", per(m.num_local_ba_iterations, m.num_local_ba),
                     per(m.num_local_ba_residuals, m.num_local_ba),
                     per(m.num_global_ba_iterations, m.num_global_ba),
                     per(m.num_global_ba_residuals, m.num_global_ba));
  out += fmt::format("{:<28}{} initial pairs tried ({} accepted), {} registered on a retry, {} "
                     "models merged, {} discarded, {} failed bundles, {} failed pose "
                     "refinements, {} poses against their neighbours in time ({} registered "
                     "from the neighbours' points, {} undone when a neighbour came later)\n",
                     "  mapper", m.num_init_trials, m.num_init_accepted, m.num_registered_on_retry,
                     m.num_models_merged, m.num_models_discarded, m.num_failed_bundles,
                     m.num_failed_pose_refinements, m.num_poses_against_neighbours,
                     m.num_poses_from_neighbours, m.num_poses_undone_by_neighbours);
  out += fmt::format("{:<28}detection {:.1f} s, {} closed ({:.1f} s), {} refused as too large "
                     "for drift\n",
                     "  loop closing", m.seconds_loop_detection, m.loops_closed.size(),
                     m.seconds_loop_closing, m.num_loops_refused);
  if (m.num_split_pairs > 0 || m.num_split_groups_refused > 0 || m.seconds_split > 0.0) {
    out += fmt::format("{:<28}{} pairs tied in {} groups, {} groups refused as too large for "
                       "drift, {:.1f} s\n",
                       "  split tracks", m.num_split_pairs, m.num_split_groups,
                       m.num_split_groups_refused, m.seconds_split);
  }
  if (!m.registrations.empty()) {
    const auto found = std::count_if(m.registrations.begin(), m.registrations.end(),
                                     [](const RegistrationRounds& r) { return r.second_pose_found; });
    out += fmt::format("{:<28}{} of {} registrations had a second plausible pose "
                       "(registrations.csv)\n",
                       "  alternate poses", found, m.registrations.size());
  }
  for (const ClosedLoop& loop : m.loops_closed) {
    // Loops found after mapping are corrected together: no time of their own.
    const std::string seconds = loop.seconds > 0.0 ? fmt::format("{:.1f} s", loop.seconds)
                                                   : std::string("corrected with the others");
    out += fmt::format("{:<28}{} -> {}: {} of {} point pairs agree, recent end moved {:.3g} "
                       "({:.2f} % of the path between), {:.2f} deg, scale {:.4f}; {}\n",
                       "  loop closed", loop.recent_frame, loop.old_frame, loop.num_inliers,
                       loop.num_correspondences, loop.correction_translation,
                       100.0 * loop.correction_fraction_of_path, loop.correction_rotation_deg,
                       loop.correction_scale, seconds);
  }
  return out;
}

std::string GlobalMapperSummary(const GlobalMapperReport& g, const MapperReport& m) {
  std::string out;
  out += fmt::format("{:<28}{} edges, {} dropped around triangles ({} nodes); {} connected "
                     "component{}, {} mapped, {} frames in the others\n",
                     "  view graph", g.num_view_graph_edges, g.view_graph.num_dropped_by_triangles,
                     g.view_graph.num_nodes, g.num_components, g.num_components == 1 ? "" : "s",
                     g.num_components_mapped, g.num_frames_in_other_components);
  if (g.num_planar_pairs > 0) {
    out += fmt::format("{:<28}{}, {} with the homography's pose, the others with F's (the one "
                       "more triangles agree with)\n",
                       "  planar pairs", g.num_planar_pairs, g.num_planar_poses_from_homography);
  }
  if (g.num_cuts > 0) {
    out += fmt::format("{:<28}{} in the video (frames next to each other without a pair), {} "
                       "pairs across left out of the view graph{}\n",
                       "  cuts", g.num_cuts, g.num_pairs_across_cuts,
                       g.num_pairs_across_cuts > 0
                           ? fmt::format("; the parts joined by their shared points in {:.1f} s",
                                         g.seconds_joining)
                           : "");
  }
  const std::string largest = g.num_components_mapped > 1 ? " (the largest component)" : "";
  out += fmt::format("{:<28}{} frames, {} L1 and {} robust iterations{}; {} edges off by more "
                     "than their bound, {} frames left without an edge\n",
                     "  rotation averaging", g.rotations.num_nodes, g.rotations.num_l1_iterations,
                     g.rotations.num_iterations, largest, g.num_rotation_outliers,
                     g.num_frames_without_edges);
  const double off_deg = GlobalPositioningOptions().max_angle_error_deg;  // not a CLI option
  out += fmt::format(
      "{:<28}{} frames, {} points, {} observations ({:.1f} % more than {:.0f} deg off), {} "
      "iterations{}{}{}\n",
      "  global positioning", g.positioning.num_cameras, g.positioning.num_points,
      g.positioning.num_observations,
      100.0 * g.positioning.LargeAngleFraction(), off_deg,
      g.positioning.num_iterations, largest,
      g.positioning.success ? "" : " (failed: " + g.positioning.termination + ")",
      g.num_bent_components > 0
          ? fmt::format("; {} component{} likely bent (see the warning)", g.num_bent_components,
                        g.num_bent_components == 1 ? "" : "s")
          : "");
  out += fmt::format("{:<28}{} global BA {:.1f} s, triangulation {:.1f} s; {} of {} frames in "
                     "{} model{}, {} dropped for seeing too few points\n",
                     "  structure", m.num_global_ba, m.seconds_global_ba, g.seconds_triangulation,
                     g.num_registered, g.num_frames, m.num_models, m.num_models == 1 ? "" : "s",
                     g.num_frames_dropped);
  if (g.largest_step_ratio > 0.0) {
    out += fmt::format("{:<28}largest step {:.1f}x the median ({} to {}){}\n", "  path",
                       g.largest_step_ratio, g.largest_step_from, g.largest_step_to,
                       g.num_broken_models > 0
                           ? fmt::format("; {} model{} likely broken (see the warning)",
                                         g.num_broken_models, g.num_broken_models == 1 ? "" : "s")
                           : "");
  }
  return out;
}

std::string SegmentSummary(const SegmentMappingReport& s) {
  std::string out;
  for (size_t k = 0; k < s.segments.size(); ++k) {
    const SegmentReport& segment = s.segments[k];
    out += fmt::format("{:<28}frames {}-{}: {} of {} registered ({} model{}), {} loop{} closed, "
                       "{:.1f} s{}{}\n",
                       fmt::format("  segment {}", k), segment.first_frame,
                       segment.first_frame + segment.num_frames - 1, segment.num_registered,
                       segment.num_frames, segment.num_models, segment.num_models == 1 ? "" : "s",
                       segment.num_loops_closed, segment.num_loops_closed == 1 ? "" : "s",
                       segment.seconds,
                       segment.resumed            ? " (from its checkpoint)"
                       : segment.global_set_aside ? " (its global model set aside as doubtful, "
                                                    "mapped incrementally)"
                                                  : "",
                       k == 0             ? ""
                       : segment.merged ? fmt::format(
                                              "; merged into the one before ({} shared points "
                                              "agree)",
                                              segment.num_merge_inliers)
                                        : "; not merged: starts a model of its own");
  }
  if (s.extended) {
    out += fmt::format("{:<28}frames left out or models apart: the incremental mapper went on "
                       "from the merged models\n",
                       "  after the merge");
  }
  return out;
}

}  // namespace

void AddReconstructCommand(CLI::App& app) {
  struct Flags {
    std::string input, output;
    ExtractFlags extract;
    MatchFlags match;
    MapFlags map;
    bool overwrite = false;
    bool all_frames = false;
    bool localized_in_model = false;
    int fill_in_rounds = 3;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* cmd = app.add_subcommand(
      "reconstruct", "Video or image folder to camera path and sparse point cloud, in one go");
  cmd->add_option("input", flags->input, "Video file (mp4, mov, mkv, avi) or folder of images")
      ->required();
  cmd->add_option("-o,--output", flags->output,
                  "Output folder (database.db, sparse/, points.ply, trajectory.txt); a run "
                  "resumes from what it holds")
      ->required();
  AddExtractFlags(cmd, &flags->extract);
  AddMatchFlags(cmd, &flags->match);
  AddMapFlags(cmd, &flags->map);
  CLI::Option* fill_in_rounds =
      cmd->add_option("--fill-in-rounds", flags->fill_in_rounds,
                      "Adaptive keyframes: rounds of in-between frames added where two "
                      "consecutive kept frames do not verify (the middle frame of the gap, then "
                      "of its halves); kept frames left unregistered after mapping get the "
                      "frames midway to their neighbours and mapping runs once more. 0: none "
                      "of this")
          ->check(CLI::NonNegativeNumber)
          ->capture_default_str();
  cmd->add_flag("--all-frames", flags->all_frames,
                "A pose for every frame: after mapping, the frames between keyframes are "
                "tracked from the keyframe before them (or after, where that fails) and "
                "localised against the map; they go "
                "to trajectory.txt, transforms.json and images/ (and OUT/localized.txt), not to "
                "the COLMAP model unless --localized-in-model");
  cmd->add_flag("--localized-in-model", flags->localized_in_model,
                "With --all-frames: also put the localised frames into sparse/0 and the gsplat "
                "layout (as images without observations)");
  cmd->add_flag("--overwrite", flags->overwrite,
                "Start again: delete OUT/database.db and the mapping checkpoints first instead "
                "of resuming from them (needed when the input or the extract / match options "
                "changed since they were made)");
  cmd->callback([=] {
    ReconstructOptions options;
    flags->map.Resolve(&options);
    options.extract = flags->extract.Resolve();
    if (fill_in_rounds->count() > 0 && options.extract.keyframes.mode == KeyframeMode::kWindows) {
      throw InvalidArgument("--fill-in-rounds fills gaps between adaptive keyframes: it cannot be "
                            "combined with fixed windows (--every, --keyframes windows)");
    }
    options.match = flags->match.Resolve();
    options.overwrite = flags->overwrite;
    if (flags->localized_in_model && !flags->all_frames) {
      throw InvalidArgument("--localized-in-model puts the frames that --all-frames localises "
                            "into the model: add --all-frames");
    }
    options.all_frames = flags->all_frames;
    options.output.localized_in_model = flags->localized_in_model;
    options.fill_in_rounds = flags->fill_in_rounds;
    const ReconstructReport report = Reconstruct(flags->input, flags->output, options);
    DeliverReport(ToJson(report), SummaryText(report));
  });
}

void AddMapCommand(CLI::App& app) {
  struct Flags {
    std::string database, output, input;
    MapFlags map;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* cmd = app.add_subcommand(
      "map", "Map a database that extract and match filled: reconstruct's mapping and export "
             "alone");
  cmd->add_option("-d,--database", flags->database,
                  "Database with frames, features and verified pairs (`loopsfm extract`, "
                  "`loopsfm match`)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", flags->output,
                  "Output folder (sparse/, points.ply, trajectory.txt, ...); mapping resumes from "
                  "its checkpoint")
      ->required();
  cmd->add_option("--input", flags->input,
                  "The video or image folder the frames came from, for the point colours and "
                  "the images and gsplat exports (default: the source the database recorded, "
                  "if it is still there)");
  AddMapFlags(cmd, &flags->map);
  cmd->callback([flags] {
    ReconstructOptions options;
    flags->map.Resolve(&options);
    const ReconstructReport report =
        MapDatabase(flags->database, flags->input, flags->output, options);
    DeliverReport(ToJson(report), SummaryText(report));
  });
}

}  // namespace loopsfm::cli
