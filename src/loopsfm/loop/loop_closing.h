#pragma once
// The incremental mapper with loop closing, as IncrementalMapperOptions::loop_closure asks:
// posegraph offers every registration to the loop closer (loop_closure.h), which corrects
// the map at once when it finds a loop; split ties the split tracks of the largest model
// together once mapping has ended (track_split.h); both does the two. With
// withhold_loop_pairs, the model is mapped without the loop pairs and its loops are closed
// at the end (CloseLoopsAfterMapping).

#include <vector>

#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/incremental_mapper.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

// RunIncrementalMapper (sfm/incremental_mapper.h) with loop closing beside it: the same
// models, progress and checkpoints, the loop closer's state saved in the checkpoints.
std::vector<Reconstruction> MapWithLoopClosing(const MapperInput& input,
                                               const IncrementalMapperOptions& options,
                                               MapperReport* report,
                                               const MapperProgress& progress = {},
                                               const MapperCheckpointing& checkpointing = {});

// The input without the pairs between frames min_frame_gap or more apart in capture order,
// tracks rebuilt from the rest: what a mapper sees when the loop pairs are withheld.
MapperInput WithoutLoopPairs(const MapperInput& input, int min_frame_gap);

// Loop closing on a finished model, for loop pairs that come after mapping: the model's
// frames and cameras are taken into a state over `input` (which holds the loop pairs), with
// its points where the loop pairs leave their tracks as they were (MapStructure::
// TakePointsOf); the other tracks are triangulated again (the two ends of a drifted loop
// get points of their own), the frames are offered to the loop closer in capture order, and
// a global refinement ends it. With loop closing disabled only the triangulation and the
// refinement run: what a global bundle adjustment makes of the loop pairs on its own.
Reconstruction CloseLoopsAfterMapping(const MapperInput& input, const Reconstruction& model,
                                      const IncrementalMapperOptions& options,
                                      MapperReport* report);

}  // namespace loopsfm
