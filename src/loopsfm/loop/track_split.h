#pragma once
// Loop closing by split tracks (`--loop-closing split`, and after the pose graph with
// `both`), on a finished model.
//
// A track may hold several 3D points (mapper_state.h): where the camera came back after
// drift, the observations of the recent pass did not fit the point the old pass made, and
// the track was split into an old point (seen only by frames long ago) and a recent one
// (seen only by frames at least min_frame_gap later). Those pairs are the loop evidence.
//
// Which splits are drift: the pairs are grouped by the stretch of the path their two ends
// lie on (one group per min_frame_gap of old and recent end), and a group is kept only when
// one similarity maps its recent points onto their old partners (LO-RANSAC, reprojection
// both ways: point_alignment.h) with at least min_num_inliers inliers and min_inlier_ratio
// of its pairs, and the correction that similarity asks for is plausible as drift (as for
// the pose graph's loops: small against the path walked between the ends, scale within
// bounds). Pairs of false matches, of a repeated facade or of a badly placed point follow
// no common similarity and are left alone; so is a group that the similarity finds already
// agreeing (points that missed merging by a few pixels).
//
// Correction: a global bundle adjustment with, for each kept pair, the term
//   w * (X_old - X_recent) / depth,  w = split_weight * focal,
// where depth is that of the pair's midpoint in the old point's median observer, a variable
// of the bundle like the points. The term is in pixels of the pair's separation as that frame
// sees it: it does not depend on the model's arbitrary scale, during the solve too (a term in
// world units would get cheaper as the model shrinks), and stays comparable to the
// reprojection errors; a few hundred pairs outweigh nothing locally yet move the frames
// between the ends. (The observer could still lower a term by backing away from the pair;
// its own reprojection terms hold it at this weight, not at a hundred times it.) That
// bundle runs over the longest tracks only (refine_points_per_frame, as after a pose-graph
// correction) with up to split_refine_ties_per_group pairs of each group, weighted to pull as
// hard as the whole group: a tied point cannot be eliminated in the Schur complement, so
// thousands of ties would make its camera system large. Then the tracks are re-triangulated
// (the two points of each pair now agree and merge), filtered, and bundled in full without
// the terms. With refine_points_per_frame 0 the terms of every pair enter one full bundle
// before that.

#include "loopsfm/math/random.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

class MapperState;

// Ties the split tracks of `model` together as above; records the groups, pairs and time in
// `report`. Returns the number of pairs tied (0: the model is left as it was).
int CloseLoopsBySplitTracks(MapperState& model, const LoopClosureOptions& options, Random& random,
                            MapperReport* report);

}  // namespace loopsfm
