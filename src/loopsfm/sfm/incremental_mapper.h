#pragma once
// Incremental Structure-from-Motion over tracks.
//
// - Initialisation by quality: candidate pairs are ranked by their well-conditioned inliers
//   (triangulation angle above a threshold, not explained by a homography); the two-view
//   model is validated (enough points after a bundle) before it grows, and the next
//   candidate is tried when it fails.
// - Growing: one frame at a time registered from 2D-3D correspondences (P3P in LO-RANSAC,
//   pose refinement), tracks triangulated as soon as two registered frames see them (a
//   track may hold several points, see mapper_state.h), local bundle adjustment after each
//   registration and global bundle adjustment (with re-triangulation, point merging and
//   filtering) whenever the model has grown by a set fraction; past global_ba_window
//   frames, only the most recent frames move in those bundles. A frame that fails to
//   register is tried again once the model sees more of it or after a global bundle.
// - Several models: frames no model can take start a new one. A model may register frames
//   of an earlier one; models linked by such shared frames or by common tracks are merged
//   through a similarity estimated robustly from their common points, then bundle adjusted
//   (model_merger.h). A grown model too small to keep is discarded and its frames stay
//   free for later models. Only what has no link stays a separate model.

#include <functional>
#include <vector>

#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

// Called after each registration with (registered in this model, frames in all).
using MapperProgress = std::function<void(size_t, size_t)>;

struct MapperCheckpoint;  // mapper_checkpoint.h

struct MapperCheckpointing {
  // Called with the mapper's state every `interval_seconds` of mapping (between two
  // registrations; 0: before every registration), and once when mapping has finished.
  std::function<void(const MapperCheckpoint&)> save;
  double interval_seconds = 60.0;
  // Where to go on from; null: from the start.
  const MapperCheckpoint* resume = nullptr;
};

// Models sorted by size, largest first. With `checkpointing`, the state is handed out now
// and then, and mapping may go on from a saved state (mapper_checkpoint.h).
std::vector<Reconstruction> RunIncrementalMapper(const MapperInput& input,
                                                 const IncrementalMapperOptions& options,
                                                 MapperReport* report,
                                                 const MapperProgress& progress = {},
                                                 const MapperCheckpointing& checkpointing = {});

}  // namespace loopsfm
