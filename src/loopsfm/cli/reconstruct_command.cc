#include <algorithm>
#include <map>

#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
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

void PrintSummary(const ReconstructReport& report) {
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
    out += GlobalMapperSummary(*report.global_mapper, report.mapper);
  } else {
    out += IncrementalMapperSummary(report.mapper);
  }
  if (report.segments) out += SegmentSummary(*report.segments);
  out += fmt::format("{:<28}{:.1f} s, peak memory {:.0f} MiB\n", "total", report.total_seconds,
                     report.peak_memory_bytes / 1048576.0);
  std::fputs(out.c_str(), stdout);
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
                     "from the neighbours' points)\n",
                     "  mapper", m.num_init_trials, m.num_init_accepted, m.num_registered_on_retry,
                     m.num_models_merged, m.num_models_discarded, m.num_failed_bundles,
                     m.num_failed_pose_refinements, m.num_poses_against_neighbours,
                     m.num_poses_from_neighbours);
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
  const std::string largest = g.num_components_mapped > 1 ? " (the largest component)" : "";
  out += fmt::format("{:<28}{} frames, {} L1 and {} robust iterations{}; {} edges off by more "
                     "than their bound, {} frames left without an edge\n",
                     "  rotation averaging", g.rotations.num_nodes, g.rotations.num_l1_iterations,
                     g.rotations.num_iterations, largest, g.num_rotation_outliers,
                     g.num_frames_without_edges);
  out += fmt::format("{:<28}{} frames, {} points, {} observations, {} iterations{}{}\n",
                     "  global positioning", g.positioning.num_cameras, g.positioning.num_points,
                     g.positioning.num_observations, g.positioning.num_iterations, largest,
                     g.positioning.success ? "" : " (failed: " + g.positioning.termination + ")");
  out += fmt::format("{:<28}{} global BA {:.1f} s, triangulation {:.1f} s; {} of {} frames in "
                     "{} model{}, {} dropped for seeing too few points\n",
                     "  structure", m.num_global_ba, m.seconds_global_ba, g.seconds_triangulation,
                     g.num_registered, g.num_frames, m.num_models, m.num_models == 1 ? "" : "s",
                     g.num_frames_dropped);
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
                       segment.seconds, segment.resumed ? " (from its checkpoint)" : "",
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
    bool text = false;
    std::string export_formats = "default";
    std::string groundtruth;
    bool no_self_calibration = false;
    std::string refine;
    std::string mapper = "incremental";
    std::string loop_closing = "posegraph";
    bool withhold_loop_pairs = false;
    bool alternate_poses = false;
    bool overwrite = false;
    bool all_frames = false;
    bool localized_in_model = false;
    int fill_in_rounds = 3;
    double checkpoint_every = 60.0;
    int segments = 1;
    int segment_overlap = 20;
    uint64_t seed = kDefaultRandomSeed;
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
  cmd->add_flag("--text", flags->text, "Also write the COLMAP model as .txt files");
  cmd->add_option("--export", flags->export_formats,
                  std::string("What to write after mapping: ") + kExportFormatsHelp +
                      "; or all, none, default (all but gsplat)")
      ->capture_default_str();
  cmd->add_option("--groundtruth", flags->groundtruth,
                  "Ground truth trajectory ('name tx ty tz qx qy qz qw' per line, "
                  "camera-to-world): the report aligns the path to it and shows its errors")
      ->check(CLI::ExistingFile);
  cmd->add_option("--refine", flags->refine,
                  "Intrinsics that global bundle adjustment refines, for every camera: any of "
                  "focal,principal-point,distortion or none (default: focal,distortion without "
                  "--intrinsics, none with)");
  cmd->add_flag("--no-self-calibration", flags->no_self_calibration,
                "Without --intrinsics, start mapping from the guessed focal length (1.2 x the "
                "image size) instead of estimating it from the pairs' fundamental matrices");
  cmd->add_option("--mapper", flags->mapper,
                      "incremental: frames registered one by one, with loop closing and "
                      "checkpoints | global: every camera at once (view-graph cleaning, rotation "
                      "averaging, global positioning of cameras and points, bundle adjustment); "
                      "loops are closed by the loop pairs in the view graph; no checkpoints")
          ->capture_default_str();
  CLI::Option* loop_closing = cmd->add_option("--loop-closing", flags->loop_closing,
                  "posegraph: when the camera returns after drift, correct the map while mapping "
                  "(Sim3 pose graph, then the two ends' points are fused) | split: after "
                  "mapping, tie the two ends of split tracks together in a bundle adjustment "
                  "(depth-normalised point constraints) | both: posegraph, then split | none: "
                  "map without loop closing")
      ->capture_default_str();
  CLI::Option* withhold = cmd->add_flag("--withhold-loop-pairs", flags->withhold_loop_pairs,
                "Evaluation: map without the pairs between frames 50 or more apart, then add "
                "them and close the loops at the end (drift grows unchecked until then; compare "
                "with --loop-closing none)");
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
                "Start again: delete OUT/database.db and OUT/mapper_checkpoint.bin first instead "
                "of resuming from them (needed when the input or the extract / match options "
                "changed since they were made)");
  CLI::Option* checkpoint_every = cmd->add_option("--checkpoint-every", flags->checkpoint_every,
                  "Save the mapping state to OUT/mapper_checkpoint.bin (with --segments, each "
                  "segment's to OUT/segments/) every this many seconds and when mapping ends; a "
                  "rerun after an interruption goes on from it (and one after a finished run "
                  "skips mapping). 0: no checkpoints")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--seed", flags->seed,
                  "Seed of the mapper's random sampling (registration RANSAC, loop closing; the "
                  "global mapper's starting positions): "
                  "a rerun with the same seed repeats the model; other seeds show how much a "
                  "result owes to chance. Matching keeps its own seed")
      ->capture_default_str();
  cmd->add_option("--segments", flags->segments,
                  "Cut the frames into this many overlapping segments in capture order, map "
                  "them at once (each with its share of --threads; under mpirun, on the "
                  "processes) with the mapper of --mapper, merge them by their shared points, "
                  "then close the loops between them (Sim3 pose graph) and refine the whole; "
                  "--checkpoint-every saves each incremental segment to OUT/segments/, and a "
                  "rerun maps only the unfinished ones. 1: the whole video at once")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  CLI::Option* segment_overlap =
      cmd->add_option("--segment-overlap", flags->segment_overlap,
                      "With --segments: frames each segment shares with the next (of the "
                      "frames kept for mapping)")
          ->check(CLI::Range(2, 1000000))
          ->capture_default_str();
  CLI::Option* alternate_poses = cmd->add_flag("--alternate-poses", flags->alternate_poses,
                "Diagnostic: after each registration, a second RANSAC over the correspondences "
                "the first rejected; writes OUT/registrations.csv (both rounds' inliers, and "
                "where a second plausible pose was found, how far it is) and plots the two "
                "rounds' inlier ratios in report.html. Does not change the mapping");
  cmd->callback([=] {
    ReconstructOptions options;
    if (flags->mapper == "global") {
      for (const CLI::Option* option : {loop_closing, withhold, checkpoint_every, alternate_poses}) {
        if (option->count() > 0) {
          throw InvalidArgument(fmt::format(
              "{} is an option of the incremental mapper; the global mapper closes loops "
              "through the loop pairs in its view graph and has no checkpoints yet: leave it "
              "out, or use --mapper incremental",
              option->get_name()));
        }
      }
      options.mapper_kind = MapperKind::kGlobal;
    } else if (flags->mapper != "incremental") {
      throw InvalidArgument(fmt::format("--mapper '{}' is not a mapper; use incremental (the "
                                        "default) or global",
                                        flags->mapper));
    }
    if (flags->segments > 1) {
      if (withhold->count() > 0) {
        throw InvalidArgument("--withhold-loop-pairs does not go with --segments: segments are "
                              "merged before the loop pairs come in already");
      }
    } else if (segment_overlap->count() > 0) {
      throw InvalidArgument("--segment-overlap is the overlap of --segments: add --segments N "
                            "(N > 1)");
    }
    options.segments.num_segments = flags->segments;
    options.segments.overlap = flags->segment_overlap;
    options.segments.sharing = Common().sharing;
    options.extract = flags->extract.Resolve();
    if (fill_in_rounds->count() > 0 && options.extract.keyframes.mode == KeyframeMode::kWindows) {
      throw InvalidArgument("--fill-in-rounds fills gaps between adaptive keyframes: it cannot be "
                            "combined with fixed windows (--every, --keyframes windows)");
    }
    options.match = flags->match.Resolve();
    options.mapper.num_threads = Common().threads;
    if (!flags->refine.empty()) {
      options.mapper.refine_known = options.mapper.refine_unknown =
          IntrinsicsRefinement::Parse(flags->refine);
    }
    const std::map<std::string, LoopClosingMethod> methods = {
        {"none", LoopClosingMethod::kNone},
        {"posegraph", LoopClosingMethod::kPoseGraph},
        {"split", LoopClosingMethod::kSplit},
        {"both", LoopClosingMethod::kBoth}};
    const auto method = methods.find(flags->loop_closing);
    if (method == methods.end()) {
      throw InvalidArgument(fmt::format("--loop-closing '{}' is not a method; use posegraph (the "
                                        "default), split, both or none",
                                        flags->loop_closing));
    }
    options.mapper.loop_closure.method = method->second;
    options.mapper.loop_closure.withhold_loop_pairs = flags->withhold_loop_pairs;
    options.mapper.record_alternate_poses = flags->alternate_poses;
    options.mapper.seed = flags->seed;
    options.overwrite = flags->overwrite;
    if (flags->localized_in_model && !flags->all_frames) {
      throw InvalidArgument("--localized-in-model puts the frames that --all-frames localises "
                            "into the model: add --all-frames");
    }
    options.all_frames = flags->all_frames;
    options.output.localized_in_model = flags->localized_in_model;
    options.fill_in_rounds = flags->fill_in_rounds;
    options.checkpoint_interval_seconds = flags->checkpoint_every;
    options.self_calibrate = !flags->no_self_calibration;
    options.output.formats = ParseExportFormats(flags->export_formats);
    options.output.write_text = flags->text;
    options.groundtruth = flags->groundtruth;
    options.show_progress = !Common().quiet;
    const ReconstructReport report = Reconstruct(flags->input, flags->output, options);
    PrintSummary(report);
  });
}

}  // namespace loopsfm::cli
