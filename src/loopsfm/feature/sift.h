#pragma once
// SIFT keypoints and descriptors (OpenCV's detector), stored the way COLMAP stores them:
// keypoints in COLMAP's pixel convention with their affine shape, descriptors normalised
// (L2, or RootSIFT) and quantised to uint8 as round(512 * value) clamped to 255.

#include <opencv2/core.hpp>

#include "loopsfm/scene/features.h"

namespace loopsfm {

struct SiftOptions {
  // Keep at most this many keypoints per frame, the strongest first.
  int max_features = 8192;
  // RootSIFT (L1-normalise, square root): better matching for the same cost.
  bool root_sift = true;
  // Contrast threshold of the detector (OpenCV's default 0.04; lower finds more, weaker points).
  double contrast_threshold = 0.02;
  // Edge threshold: larger keeps more edge-like keypoints.
  double edge_threshold = 10.0;
  // Scale levels per octave.
  int num_octave_layers = 3;
  // Resize frames by this factor before detection (for low-resolution video); keypoints are
  // mapped back to the original resolution, so cameras and models stay in original pixels.
  double upscale = 1.0;
  void Check() const;
};

// Extracts SIFT features from an 8-bit grey or BGR image. Single-threaded per call; run
// frames in parallel from the caller. Also returns the BGR colour under each keypoint in
// `colors` when it is non-null (used for coloured point clouds).
FeatureSet ExtractSift(const cv::Mat& image, const SiftOptions& options,
                       std::vector<Eigen::Matrix<uint8_t, 3, 1>>* colors = nullptr);

// Normalises float descriptors in place (L2, or RootSIFT) and quantises them like COLMAP.
FeatureDescriptors QuantizeDescriptors(const cv::Mat& float_descriptors, bool root_sift);

}  // namespace loopsfm
