#pragma once
// Flags of mapping and its outputs, shared by `reconstruct` and `map`.

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "loopsfm/math/random.h"
#include "loopsfm/pipeline/reconstruct.h"

namespace loopsfm::cli {

struct MapFlags {
  std::string mapper = "incremental";
  std::string loop_closing = "posegraph";
  bool withhold_loop_pairs = false;
  bool alternate_poses = false;
  bool keep_global_model = false;
  bool no_self_calibration = false;
  std::string refine;
  double checkpoint_every = 60.0;
  int segments = 1;
  int segment_overlap = 20;
  uint64_t seed = kDefaultRandomSeed;
  bool text = false;
  std::string export_formats = "default";
  std::string groundtruth;
  // The options among them that only some mappers take, to refuse them elsewhere.
  CLI::Option* loop_closing_option = nullptr;
  CLI::Option* withhold_option = nullptr;
  CLI::Option* alternate_poses_option = nullptr;
  CLI::Option* keep_global_option = nullptr;
  CLI::Option* segment_overlap_option = nullptr;
  // Sets the mapper, self-calibration, segment and output fields of `options` from the flags;
  // InvalidArgument for flags that do not go together.
  void Resolve(ReconstructOptions* options) const;
};
// `checkpoint_path`: what --checkpoint-every's help names as the checkpoint file.
void AddMapFlags(CLI::App* cmd, MapFlags* flags);

}  // namespace loopsfm::cli
