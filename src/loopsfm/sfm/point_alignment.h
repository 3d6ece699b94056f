#pragma once
// A similarity between two sets of 3D points made from the same tracks, estimated robustly:
// used to merge two models (model_merger.h) and to measure a loop inside one model
// (loop/loop_closure.h), where the two ends of a drifted loop hold different points of one track.
//
// LO-RANSAC over Umeyama on minimal samples of three, re-estimated on the inliers; a
// correspondence is an inlier when the moved point reprojects within the threshold in a
// frame observing its partner, both ways, which is scale-free and tolerant of points
// poorly placed along their rays.
#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"
#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

// One observation of a point: the frame, its camera and the keypoint position.
struct PointObservation {
  const Image* image = nullptr;
  const Camera* camera = nullptr;
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
};

// The first observation of a point's track in the reconstruction (pointers into it).
PointObservation FirstObservation(const Reconstruction& reconstruction, const Point3D& point);

// Two points of one track: one in the source, one in the destination, each with an
// observation of it.
struct PointCorrespondence {
  Eigen::Vector3d src_xyz = Eigen::Vector3d::Zero();
  Eigen::Vector3d dst_xyz = Eigen::Vector3d::Zero();
  PointObservation src_obs, dst_obs;
};

struct PointAlignment {
  bool success = false;
  int num_inliers = 0;
  std::vector<char> inlier_mask;
  Sim3d dst_from_src;
};

// dst_from_src from the correspondences; success when a model with at least three inliers
// was found (the caller judges whether that is enough).
PointAlignment AlignPointSets(const std::vector<PointCorrespondence>& correspondences,
                              double max_reproj_error_px, int max_num_trials, Random& random);

// Which correspondences dst_from_src explains within the threshold (same residual as above).
std::vector<char> AlignmentInliers(const std::vector<PointCorrespondence>& correspondences,
                                   const Sim3d& dst_from_src, double max_reproj_error_px);

}  // namespace loopsfm
