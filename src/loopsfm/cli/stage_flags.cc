#include "loopsfm/cli/stage_flags.h"

#include <algorithm>
#include <filesystem>

#include "loopsfm/cli/common.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/util/errors.h"

namespace loopsfm::cli {

void AddExtractFlags(CLI::App* cmd, ExtractFlags* flags) {
  cmd->add_option("--intrinsics", flags->intrinsics,
                  "Known camera, one line 'MODEL width height params...' in COLMAP's order, e.g. "
                  "'PINHOLE 1920 1080 1500 1500 960 540' (held fixed unless --refine says "
                  "otherwise); without it the focal length is self-calibrated");
  cmd->add_option("--camera-model", flags->camera_model,
                  "Camera model without --intrinsics (default SIMPLE_RADIAL): " +
                      CameraModelNameList());
  cmd->add_option("--keyframes", flags->keyframes,
                  "Which frames to keep: auto (default: adaptive for a video, every image of a "
                  "folder) | adaptive (a new keyframe when the view has moved: parallax or "
                  "overlap, the sharpest frame near that point) | windows (one frame in every "
                  "--every N)");
  flags->every = cmd->add_option("--every", flags->options.keyframes.every,
                                 "Keep one frame in N, the sharpest of each window (fixed windows "
                                 "instead of adaptive keyframes; 1 keeps every frame)")
                     ->capture_default_str();
  cmd->add_flag("--first-of-window", flags->first_of_window,
                "With --every, keep the first frame of each window instead of the sharpest");
  flags->adaptive_flags = {
      cmd->add_option("--keyframe-parallax", flags->options.keyframes.adaptive.min_parallax_deg,
                      "Adaptive keyframes: a new keyframe once the median parallax (the part of "
                      "the motion of tracked corners that no rotation explains) reaches this "
                      "many degrees (implies --keyframes adaptive)")
          ->capture_default_str(),
      cmd->add_option("--keyframe-overlap",
                      flags->options.keyframes.adaptive.min_tracked_fraction,
                      "Adaptive keyframes: ... or once fewer than this fraction of the last "
                      "keyframe's corners are still tracked (implies --keyframes adaptive)")
          ->capture_default_str()};
  cmd->add_option("--upscale", flags->options.sift.upscale,
                  "Upscale frames by this factor before SIFT (low-resolution video)")
      ->capture_default_str();
  cmd->add_option("--max-image-size", flags->options.sift.max_image_size,
                  "Downscale frames whose longer side is larger than this before SIFT (keypoints "
                  "stay in the frame's pixels); bounds memory for 4K and 8K video")
      ->capture_default_str();
  cmd->add_option("--max-features", flags->options.sift.max_features, "Most features per frame")
      ->capture_default_str();
  cmd->add_flag("--no-root-sift", flags->no_root_sift, "Plain L2-normalised SIFT descriptors");
}

ExtractOptions ExtractFlags::Resolve() const {
  ExtractOptions resolved = options;
  resolved.keyframes.sharpest = !first_of_window;
  if (!keyframes.empty()) resolved.keyframes.mode = ParseKeyframeMode(keyframes);
  if (every != nullptr && every->count() > 0) {
    if (resolved.keyframes.mode == KeyframeMode::kAdaptive) {
      throw InvalidArgument(fmt::format("--every {} keeps fixed windows: it cannot be combined "
                                        "with --keyframes adaptive; drop one of them",
                                        resolved.keyframes.every));
    }
    resolved.keyframes.mode = KeyframeMode::kWindows;
  }
  for (const CLI::Option* flag : adaptive_flags) {
    if (flag->count() == 0) continue;
    if (resolved.keyframes.mode == KeyframeMode::kWindows) {
      throw InvalidArgument(fmt::format("{} tunes adaptive keyframes: it cannot be combined with "
                                        "fixed windows (--every, --keyframes windows)",
                                        flag->get_name()));
    }
    resolved.keyframes.mode = KeyframeMode::kAdaptive;
  }
  if (first_of_window && resolved.keyframes.mode != KeyframeMode::kWindows) {
    throw InvalidArgument("--first-of-window applies to fixed windows: add --every N (or "
                          "--keyframes windows)");
  }
  resolved.sift.root_sift = !no_root_sift;
  resolved.num_threads = Common().threads;
  resolved.sharing = Common().sharing;
  resolved.show_progress = !Common().quiet;
  resolved.hooks = Common().hooks;
  if (!intrinsics.empty()) resolved.intrinsics = ReadIntrinsicsFile(intrinsics);
  if (!camera_model.empty()) {
    resolved.camera_model = ParseCameraModel(camera_model);
    if (resolved.intrinsics && resolved.intrinsics->model_id != resolved.camera_model) {
      throw InvalidArgument(fmt::format(
          "--camera-model {} disagrees with the {} camera of --intrinsics '{}'; the intrinsics "
          "file names its model, drop --camera-model", camera_model,
          resolved.intrinsics->ModelName(), intrinsics));
    }
  }
  resolved.Check();
  return resolved;
}

void AddMatchFlags(CLI::App* cmd, MatchFlags* flags) {
  cmd->add_option("--pairs", flags->pairs,
                  "Pairing strategy: vocabtree (default: sequential neighbours, vocabulary-tree loop "
                  "detection, bridging where the view graph falls apart) | sequential (a fixed "
                  "window of following frames) | exhaustive | lowres (exhaustive with a "
                  "low-resolution prefilter)");
  cmd->add_option("--vocab", flags->vocab, "Vocabulary tree file from `loopsfm vocab build` "
                  "(default: train one on the scene's own descriptors)");
  cmd->add_option("--vocab-branching", flags->options.vocab_tree.branching,
                  "Vocabulary tree branching factor k")->capture_default_str();
  cmd->add_option("--vocab-depth", flags->options.vocab_tree.depth, "Vocabulary tree depth L")
      ->capture_default_str();
  cmd->add_option("--proposals", flags->options.guided.num_proposals,
                  "Vocabtree: best-scoring pairs proposed in the first round (0: number of "
                  "frames); later rounds propose as many as the round before verified")
      ->capture_default_str();
  cmd->add_option("--stop-failure-ratio", flags->options.guided.max_failure_ratio,
                  "Vocabtree: stop proposing by score when more than this fraction of a "
                  "round's score proposals fail (region growing goes on while it verifies)")
      ->capture_default_str();
  cmd->add_option("--loop-partners", flags->options.guided.max_loop_partners,
                  "Vocabtree: stop proposing loop pairs between two frames that both have this "
                  "many verified partners beyond the sequential window (0: no limit, match "
                  "every loop pair region growing reaches)")
      ->capture_default_str();
  cmd->add_option("--similarity-out", flags->options.similarity_path,
                  "Vocabtree: also write the similarity matrix as text (a line of frame names, "
                  "then one row of scores per frame)");
  cmd->add_option("--overlap", flags->options.sequential.overlap,
                  "Sequential: match each frame with this many previous frames")
      ->capture_default_str();
  cmd->add_option("--ratio", flags->options.matcher.max_ratio,
                  "Lowe's ratio test threshold (0.8 default; 0.7 and 0.5 are stricter)")
      ->capture_default_str();
  cmd->add_option("--match-kernel", flags->match_kernel,
                  "Descriptor matching kernel: auto (the fastest this CPU runs), avx512-vnni, "
                  "avx2, neon-dotprod, neon or float. All give identical matches; naming one "
                  "measures or tests it (refused where the CPU lacks it)")
      ->envname("LOOPSFM_MATCH_KERNEL")
      ->capture_default_str();
  cmd->add_option("--max-error", flags->options.verification.max_error,
                  "RANSAC inlier threshold in pixels")
      ->capture_default_str();
  cmd->add_option("--min-inliers", flags->options.verification.min_num_inliers,
                  "Reject pairs with fewer inliers")
      ->capture_default_str();
}

MatchOptions MatchFlags::Resolve() const {
  MatchOptions resolved = options;
  // Videos and ordered image folders alike: sequential neighbours plus loop detection, so
  // loops are found without a flag.
  resolved.strategy = ParsePairStrategy(pairs.empty() ? "vocabtree" : pairs);
  // The wider window of the first frames is never narrower than the requested overlap.
  resolved.sequential.initial_overlap =
      std::max(resolved.sequential.initial_overlap, resolved.sequential.overlap);
  if (!vocab.empty()) resolved.vocab_path = vocab;
  if (!resolved.similarity_path.empty()) {
    // Checked before any matching, so a typo does not cost a run.
    if (resolved.strategy != PairStrategy::kVocabTree) {
      throw InvalidArgument("--similarity-out needs --pairs vocabtree (only the vocabulary tree "
                            "computes a similarity matrix)");
    }
    const std::filesystem::path folder =
        std::filesystem::absolute(resolved.similarity_path).parent_path();
    if (!std::filesystem::is_directory(folder)) {
      throw InvalidArgument(fmt::format("--similarity-out: folder '{}' does not exist; create it "
                                        "or choose another path", folder.string()));
    }
  }
  try {
    resolved.matcher.kernel = ParseDescriptorKernel(match_kernel);
    resolved.matcher.Check();
  } catch (const InvalidArgument& e) {
    throw InvalidArgument(fmt::format("--match-kernel (or LOOPSFM_MATCH_KERNEL): {}", e.what()));
  }
  resolved.num_threads = Common().threads;
  resolved.sharing = Common().sharing;
  resolved.show_progress = !Common().quiet;
  resolved.hooks = Common().hooks;
  resolved.Check();
  return resolved;
}

}  // namespace loopsfm::cli
