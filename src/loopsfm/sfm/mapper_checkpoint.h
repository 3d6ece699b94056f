#pragma once
// The incremental mapper's whole state between two registrations, so a long mapping can be
// saved now and then and, after an interruption, resumed to the same result as a run that
// was never interrupted (with one thread: Ceres' multi-threaded sums may round differently).
// pipeline/mapper_checkpoint.h writes it to a file and reads it back.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

struct MapperCheckpoint {
  struct Model {
    MappedState state;
    image_t gauge1 = kInvalidImageId, gauge2 = kInvalidImageId;
    // Failed merges with this model (after which its frames are left alone).
    int merge_failures = 0;
  };
  // Mapping had finished: `kept` holds the final models, largest first.
  bool finished = false;
  std::vector<Model> kept;
  // The model being grown, and where its growth stood.
  std::optional<Model> growing;
  // Frames that failed to register (with the visible track count then) and frames that
  // failed at least once; the size at the last global refinement (whole or windowed); the
  // frames registered most recently, oldest first (IncrementalMapperOptions::
  // global_ba_window); whether the model was refined since it last stalled.
  std::vector<std::pair<image_t, uint64_t>> failed_at;
  std::vector<image_t> ever_failed;
  uint64_t last_global_size = 0;
  std::vector<image_t> recent_frames;
  bool refined_since_stall = false;
  // Initial pair candidates tried so far (RankInitialPairs order).
  std::vector<char> tried_initial_pairs;
  // Random::State() of the mapper's and the loop closer's generators.
  std::string random_state, loop_random_state;
  // The loop closer's window of registrations with loop evidence, and its cooldown.
  std::vector<image_t> loop_window;
  int loop_cooldown = 0;
  // What the report held then (counters, timings, loops closed).
  MapperReport report;
  // Registered frames in all models (for messages).
  size_t NumRegistered() const {
    size_t n = growing ? growing->state.registered.size() : 0;
    for (const Model& model : kept) n += model.state.registered.size();
    return n;
  }
};

}  // namespace loopsfm
