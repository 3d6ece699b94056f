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
// - Loop closing is not done here: it runs beside the mapper through a MapperHook
//   (loop/loop_closing.h), told of every registration and of the end of mapping.

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
class MapperState;        // mapper_state.h

// What runs beside the mapper (loop closing): told of each registration and of the end of
// mapping, and saved with the mapper's state in its checkpoints.
class MapperHook {
 public:
  virtual ~MapperHook() = default;
  // After `image_id` was registered in `model` and its local bundle ran. Returns true when
  // it changed the model and ended with a global refinement (the mapper then counts the
  // model as refined).
  virtual bool AfterRegistration(MapperState& model, image_t image_id, MapperReport* report) = 0;
  // Once every model is grown and merged, with the largest, before the final checkpoint.
  virtual void AfterMapping(MapperState& largest, MapperReport* report) = 0;
  // Its state between registrations, into and from a checkpoint. Restore throws InputError
  // for a state that is not one.
  virtual void Save(MapperCheckpoint* checkpoint) const = 0;
  virtual void Restore(const MapperCheckpoint& checkpoint) = 0;
};

struct MapperCheckpointing {
  // Called with the mapper's state every `interval_seconds` of mapping (between two
  // registrations; 0: before every registration), and once when mapping has finished.
  std::function<void(const MapperCheckpoint&)> save;
  double interval_seconds = 60.0;
  // Where to go on from; null: from the start.
  const MapperCheckpoint* resume = nullptr;
};

// Models sorted by size, largest first. With `checkpointing`, the state is handed out now
// and then, and mapping may go on from a saved state (mapper_checkpoint.h). `hook` (may be
// null) runs beside the mapper; options.loop_closure is read only by the hook and by the
// refinement after a loop correction (MapperState::RefineAfterCorrection).
std::vector<Reconstruction> RunIncrementalMapper(const MapperInput& input,
                                                 const IncrementalMapperOptions& options,
                                                 MapperReport* report,
                                                 const MapperProgress& progress = {},
                                                 const MapperCheckpointing& checkpointing = {},
                                                 MapperHook* hook = nullptr);

// The incremental mapper going on from models mapped before, of the same frames (from this
// input or parts of it, InputPart): each takes over a model's poses and triangulates its
// tracks; the largest then grows by the frames no model has, merging with the others where
// it meets them, and mapping goes on as RunIncrementalMapper's from the frames left. Models
// sorted by size, largest first; no checkpoints.
std::vector<Reconstruction> ExtendIncrementalModels(const MapperInput& input,
                                                    const IncrementalMapperOptions& options,
                                                    const std::vector<Reconstruction>& models,
                                                    MapperReport* report,
                                                    MapperHook* hook = nullptr);

}  // namespace loopsfm
