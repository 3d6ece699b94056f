#pragma once
// Stage 4 of the global mapper (global_mapper.h): the model at the positioned poses, its
// tracks triangulated and refined, in two steps so a checkpoint can sit between them.
//
// The positions are rough, so the first bundles accept reprojection errors
// GlobalMapperOptions::loose_error_factor times the usual bound (a track that does not fit
// its frames within the bound would be split into several points, and frames held by few
// points), over each frame's best points only: they correct the poses and the cameras. The
// model is then triangulated again under the usual bound and refined whole.

#include <map>
#include <optional>
#include <vector>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/global_mapper_options.h"
#include "loopsfm/sfm/global_mapper_report.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"
#include "loopsfm/util/progress.h"

namespace loopsfm {

// The loose bundles from `poses` (cam_from_world): the cameras and poses after them, without
// points; nullopt when fewer than two frames could be placed. `hooks` (may be null) are
// polled before each round.
std::optional<MappedState> LooseBundles(const MapperInput& input,
                                        const IncrementalMapperOptions& mapper_options,
                                        const GlobalMapperOptions& options,
                                        const std::map<image_t, Rigid3d>& poses,
                                        const RunHooks* hooks, GlobalMapperReport* report,
                                        MapperReport* mapper_report);

// The model at the poses and cameras of `loose`, triangulated under the usual bound, refined,
// and without the frames that see fewer than min_frame_points points; nullopt when fewer
// than two frames are left. Without `refine`, for a model that the bundles of the join
// across cuts refine anyway (GlobalMapperOptions::split_at_cuts), the refinement rounds are
// left out.
std::optional<Reconstruction> RefinedModel(const MapperInput& input,
                                           const IncrementalMapperOptions& mapper_options,
                                           const GlobalMapperOptions& options,
                                           const MappedState& loose, bool refine,
                                           const RunHooks* hooks, GlobalMapperReport* report,
                                           MapperReport* mapper_report);

// Warns of the models whose path jumps between two frames next in capture order by more than
// GlobalMapperOptions::max_step_ratio times the median step (global positioning can lose the
// scale between parts of a video); the report gets the first model's largest jump and the
// count of such models.
void CheckPathJumps(const MapperInput& input, const std::vector<Reconstruction>& models,
                    const GlobalMapperOptions& options, GlobalMapperReport* report);

}  // namespace loopsfm
