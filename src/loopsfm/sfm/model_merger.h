#pragma once
// Merging two models of the same scene that share tracks (frames registered in both, or
// verified pairs between their frames).
//
// Correspondences are pairs of 3D points made from one track, one in each model. A
// similarity dst_from_src is estimated from them with LO-RANSAC (Umeyama on minimal samples
// of three, re-estimated on the inliers); a correspondence is an inlier when the moved
// point reprojects within the threshold in a frame of the other model observing it, both
// ways, which is scale-free and tolerant of points poorly placed along their rays.
// Then the source's frames and points are moved into the destination: frames it lacks
// are registered with their moved poses, points join a point of their track that they fit
// or become points of their own.

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"

namespace loopsfm {

class MapperState;

struct ModelMergeReport {
  bool success = false;
  int num_correspondences = 0;
  int num_inliers = 0;
  Sim3d dst_from_src;
  // Frames of the source registered into the destination, and points moved over (joined to
  // an existing point of their track, or added).
  int num_images_added = 0;
  int num_points_joined = 0;
  int num_points_added = 0;
};

// Estimates the alignment and, when it is supported by at least merge_min_num_inliers
// correspondences and merge_min_inlier_ratio of them, merges src into dst. Both states must
// come from the same MapperInput. dst is left unchanged when the merge is refused. No
// bundle adjustment is run here: the caller refines the merged model.
ModelMergeReport MergeModels(MapperState& dst, const MapperState& src, Random& random);

}  // namespace loopsfm
