#include "loopsfm/cli/map_flags.h"

#include <map>

#include <fmt/format.h>

#include "loopsfm/cli/common.h"
#include "loopsfm/cli/stage_flags.h"
#include "loopsfm/util/errors.h"

namespace loopsfm::cli {

void AddMapFlags(CLI::App* cmd, MapFlags* flags) {
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
                      "loops are closed by the loop pairs in the view graph; checkpoints after "
                      "each stage")
          ->capture_default_str();
  flags->keep_global_option = cmd->add_flag(
      "--keep-global-model", flags->keep_global_model,
      "With --mapper global: keep its model where it warns that the path is likely bent "
      "(many wrong matches, as repeated structure gives) or broken (a jump in the path), "
      "instead of setting it aside and mapping the video again with the incremental mapper");
  flags->loop_closing_option = cmd->add_option("--loop-closing", flags->loop_closing,
                  "posegraph: when the camera returns after drift, correct the map while mapping "
                  "(Sim3 pose graph, then the two ends' points are fused) | split: after "
                  "mapping, tie the two ends of split tracks together in a bundle adjustment "
                  "(depth-normalised point constraints) | both: posegraph, then split | none: "
                  "map without loop closing")
      ->capture_default_str();
  flags->withhold_option = cmd->add_flag("--withhold-loop-pairs", flags->withhold_loop_pairs,
                "Evaluation: map without the pairs between frames 50 or more apart, then add "
                "them and close the loops at the end (drift grows unchecked until then; compare "
                "with --loop-closing none)");
  cmd->add_option("--checkpoint-every", flags->checkpoint_every,
                  "Save the mapping state to OUT/mapper_checkpoint.bin (with --segments, each "
                  "segment's to OUT/segments/) every this many seconds and when mapping ends; a "
                  "rerun after an interruption goes on from it (and one after a finished run "
                  "skips mapping). The global mapper saves to OUT/global_mapper_checkpoint.bin "
                  "after each of its stages instead, whatever the number. 0: no checkpoints")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--seed", flags->seed,
                  "Seed of the mapper's random sampling (registration RANSAC, loop closing; the "
                  "global mapper's starting positions): "
                  "a rerun with the same seed repeats the model; other seeds show how much a "
                  "result owes to chance. Matching keeps its own seed")
      ->capture_default_str();
  cmd->add_option("--segments", flags->segments,
                  "Cut the frames into this many overlapping segments in capture order, of about "
                  "equal cost (their keypoints in tracks), map them at once (each with its share of --threads; under mpirun, on the "
                  "processes) with the mapper of --mapper, merge them by their shared points, "
                  "then close the loops between them (Sim3 pose graph) and refine the whole; "
                  "--checkpoint-every saves each incremental segment to OUT/segments/, and a "
                  "rerun maps only the unfinished ones. 1: the whole video at once")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  flags->segment_overlap_option =
      cmd->add_option("--segment-overlap", flags->segment_overlap,
                      "With --segments: frames each segment shares with the next (of the "
                      "frames kept for mapping)")
          ->check(CLI::Range(2, 1000000))
          ->capture_default_str();
  flags->alternate_poses_option = cmd->add_flag("--alternate-poses", flags->alternate_poses,
                "Diagnostic: after each registration, a second RANSAC over the correspondences "
                "the first rejected; writes OUT/registrations.csv (both rounds' inliers, and "
                "where a second plausible pose was found, how far it is) and plots the two "
                "rounds' inlier ratios in report.html. Does not change the mapping");
}

void MapFlags::Resolve(ReconstructOptions* options) const {
  if (mapper == "global") {
    for (const CLI::Option* option :
         {loop_closing_option, withhold_option, alternate_poses_option}) {
      if (option->count() > 0) {
        throw InvalidArgument(fmt::format(
            "{} is an option of the incremental mapper; the global mapper closes loops "
            "through the loop pairs in its view graph: leave it out, or use --mapper "
            "incremental",
            option->get_name()));
      }
    }
    options->mapper_kind = MapperKind::kGlobal;
    options->remap_doubtful_global = !keep_global_model;
  } else if (mapper != "incremental") {
    throw InvalidArgument(fmt::format("--mapper '{}' is not a mapper; use incremental (the "
                                      "default) or global",
                                      mapper));
  } else if (keep_global_option->count() > 0) {
    throw InvalidArgument("--keep-global-model is an option of the global mapper: add --mapper "
                          "global, or leave it out");
  }
  if (segments > 1) {
    if (withhold_option->count() > 0) {
      throw InvalidArgument("--withhold-loop-pairs does not go with --segments: segments are "
                            "merged before the loop pairs come in already");
    }
  } else if (segment_overlap_option->count() > 0) {
    throw InvalidArgument("--segment-overlap is the overlap of --segments: add --segments N "
                          "(N > 1)");
  }
  options->segments.num_segments = segments;
  options->segments.overlap = segment_overlap;
  options->segments.sharing = Common().sharing;
  options->mapper.num_threads = Common().threads;
  if (!refine.empty()) {
    options->mapper.refine_known = options->mapper.refine_unknown =
        IntrinsicsRefinement::Parse(refine);
  }
  const std::map<std::string, LoopClosingMethod> methods = {
      {"none", LoopClosingMethod::kNone},
      {"posegraph", LoopClosingMethod::kPoseGraph},
      {"split", LoopClosingMethod::kSplit},
      {"both", LoopClosingMethod::kBoth}};
  const auto method = methods.find(loop_closing);
  if (method == methods.end()) {
    throw InvalidArgument(fmt::format("--loop-closing '{}' is not a method; use posegraph (the "
                                      "default), split, both or none",
                                      loop_closing));
  }
  options->mapper.loop_closure.method = method->second;
  options->mapper.loop_closure.withhold_loop_pairs = withhold_loop_pairs;
  options->mapper.record_alternate_poses = alternate_poses;
  options->mapper.seed = seed;
  options->checkpoint_interval_seconds = checkpoint_every;
  options->self_calibrate = !no_self_calibration;
  options->output.formats = ParseExportFormats(export_formats);
  options->output.write_text = text;
  options->groundtruth = groundtruth;
  options->show_progress = !Common().quiet;
  options->hooks = Common().hooks;
}

}  // namespace loopsfm::cli
