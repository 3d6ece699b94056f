#pragma once
// Keypoints, descriptors and matches as stored in COLMAP databases.

#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/util/types.h"

namespace loopsfm {

// A keypoint with its affine shape (COLMAP's 6-column layout). (x, y) in COLMAP's pixel
// convention: the centre of the top-left pixel is (0.5, 0.5).
struct FeatureKeypoint {
  float x = 0, y = 0;
  float a11 = 1, a12 = 0, a21 = 0, a22 = 1;

  static FeatureKeypoint FromScaleOrientation(float x, float y, float scale, float orientation) {
    const float c = std::cos(orientation), s = std::sin(orientation);
    return {x, y, scale * c, -scale * s, scale * s, scale * c};
  }
  float Scale() const { return 0.5f * (std::hypot(a11, a21) + std::hypot(a12, a22)); }
  float Orientation() const { return std::atan2(a21, a11); }
};
using FeatureKeypoints = std::vector<FeatureKeypoint>;

inline constexpr int kDescriptorDim = 128;
// One SIFT descriptor per row, quantised to uint8 as COLMAP stores them.
using FeatureDescriptors = Eigen::Matrix<uint8_t, Eigen::Dynamic, kDescriptorDim, Eigen::RowMajor>;

// Keypoints and descriptors of one frame, row i of descriptors belonging to keypoint i.
struct FeatureSet {
  FeatureKeypoints keypoints;
  FeatureDescriptors descriptors;
  size_t Size() const { return keypoints.size(); }
};

struct FeatureMatch {
  point2D_t point2D_idx1 = kInvalidPoint2DIdx;
  point2D_t point2D_idx2 = kInvalidPoint2DIdx;
  friend bool operator==(const FeatureMatch&, const FeatureMatch&) = default;
};
using FeatureMatches = std::vector<FeatureMatch>;

}  // namespace loopsfm
