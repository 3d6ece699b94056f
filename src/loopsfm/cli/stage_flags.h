#pragma once
// Flags of the extract and match stages, shared by `extract`, `match` and `reconstruct`.

#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "loopsfm/pipeline/extract.h"
#include "loopsfm/pipeline/match.h"

namespace loopsfm::cli {

struct ExtractFlags {
  std::string intrinsics;
  std::string camera_model;
  ExtractOptions options;
  // Empty: auto (adaptive for a video, every image of a folder; windows when --every is given).
  std::string keyframes;
  CLI::Option* every = nullptr;
  // --keyframe-parallax and --keyframe-overlap: given, they ask for adaptive keyframes.
  std::vector<CLI::Option*> adaptive_flags;
  bool first_of_window = false;
  bool no_root_sift = false;
  // Options with the flags applied (reads the intrinsics file).
  ExtractOptions Resolve() const;
};
void AddExtractFlags(CLI::App* cmd, ExtractFlags* flags);

struct MatchFlags {
  // Empty: the default, vocabtree.
  std::string pairs;
  MatchOptions options;
  std::string vocab;
  std::string match_kernel = "auto";
  MatchOptions Resolve() const;
};
void AddMatchFlags(CLI::App* cmd, MatchFlags* flags);

// What each export format writes, for the help of `reconstruct --export` and `export --format`.
inline constexpr const char* kExportFormatsHelp =
    "any of colmap (sparse/<k>), ply (points.ply), tum (trajectory.txt), images (images/: the "
    "frames), nerfstudio (transforms.json), gsplat (undistorted/: PINHOLE images and model), report "
    "(report.html, reconstruct only)";

}  // namespace loopsfm::cli
