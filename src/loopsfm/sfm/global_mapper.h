#pragma once
// Global Structure-from-Motion (the thesis' chapter 7.2; GLOMAP, Pan et al., ECCV 2024):
// every camera at once instead of one after another, so errors spread evenly instead of
// adding up along the path, and loops are closed by the loop pairs in the view graph.
//
//  1. View graph: one edge per verified pair with a relative pose (the intrinsics given or
//     self-calibrated before), weighted by its inliers; edges whose rotation disagrees
//     around triangles are dropped (matching/view_graph_cleaning.h). Each connected
//     component left is mapped on its own through the stages below.
//  2. Rotation averaging (estimators/rotation_averaging.h): every frame's rotation; edges
//     that disagree with the result are counted out.
//  3. Global positioning (estimators/global_positioning.h): camera centres and track
//     positions together from the observations' bearings, with bounded residuals, from a
//     start along the video's order. Camera-to-camera translation averaging degenerates where the camera
//     moves along its own path, which is most of a video; the points make it well posed.
//  4. Structure (global_structure.h): every track triangulated from the poses (a track may
//     hold several points, map_structure.h), then rounds of global bundle adjustment with
//     re-triangulation, point merging and filtering.
//
// The bundle, triangulation and filtering settings are the incremental mapper's
// (IncrementalMapperOptions), so both mappers refine a model the same way.

#include <vector>

#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/global_mapper_checkpoint.h"
#include "loopsfm/sfm/global_mapper_options.h"
#include "loopsfm/sfm/global_mapper_report.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"
#include "loopsfm/util/progress.h"

namespace loopsfm {

// A model per connected component of the cleaned view graph with at least the mapper
// options' min_model_size frames (at most max_num_models), largest first; none for a
// component where a stage fails (the log says which). `mapper_report` gets the bundle
// counts and times as the incremental mapper reports them. `hooks` (may be null) are polled
// between the stages and the bundle rounds: a stop throws Cancelled. With `checkpointing`,
// the progress is handed out after each stage (of each component), and mapping may go on
// from a saved one (global_mapper_checkpoint.h).
std::vector<Reconstruction> RunGlobalMapper(const MapperInput& input,
                                            const IncrementalMapperOptions& mapper_options,
                                            const GlobalMapperOptions& options,
                                            GlobalMapperReport* report,
                                            MapperReport* mapper_report,
                                            const RunHooks* hooks = nullptr,
                                            const GlobalMapperCheckpointing& checkpointing = {});

}  // namespace loopsfm
