#pragma once
// One edge of the view graph for global mapping: the measured relative rotation of an image
// pair (e.g. TwoViewGeometry::cam2_from_cam1.rotation) and how much it is trusted. View-graph
// cleaning (matching/) and rotation averaging (estimators/) both read lists of these.
//
// With R_k = cam_k_from_world (COLMAP's convention), a consistent measurement is
// cam2_from_cam1 = R_2 * R_1^T.

#include <Eigen/Geometry>

#include "loopsfm/util/types.h"

namespace loopsfm {

struct RelativeRotation {
  image_t node1 = kInvalidImageId;
  image_t node2 = kInvalidImageId;
  Eigen::Quaterniond cam2_from_cam1 = Eigen::Quaterniond::Identity();
  // Confidence of the measurement, e.g. the pair's number of inlier matches; > 0.
  double weight = 1.0;
};

}  // namespace loopsfm
