#pragma once
// The verified geometry of one image pair, kept for the mapper and for loop closing.

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/features.h"

namespace loopsfm {

struct TwoViewGeometry {
  // COLMAP's configuration codes (stored in the database's two_view_geometries.config).
  enum Config : int {
    kUndefined = 0,
    kDegenerate = 1,
    kCalibrated = 2,
    kUncalibrated = 3,
    kPlanar = 4,
    kPanoramic = 5,
    kPlanarOrPanoramic = 6,
    kWatermark = 7,
    kMultiple = 8,
  };

  int config = kUndefined;
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  // Relative pose (x_cam2 = R x_cam1 + t): unit-length translation for kCalibrated,
  // kUncalibrated (from the guessed intrinsics) and kPlanar; zero translation for kPanoramic.
  Rigid3d cam2_from_cam1;
  // The matches consistent with the geometry (indices into the two images' keypoints).
  FeatureMatches inlier_matches;

  bool IsVerified() const {
    return config != kUndefined && config != kDegenerate && !inlier_matches.empty();
  }
};

}  // namespace loopsfm
