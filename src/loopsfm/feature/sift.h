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
  // Frames whose longer side (after upscale) exceeds this many pixels are downscaled to it
  // before detection, as COLMAP's max_image_size; keypoints are mapped back the same way.
  // It bounds SIFT's memory per frame: the scale space (the frame doubled, then 6 blurred and
  // 5 difference images per octave, in floats) takes about 235 bytes per pixel it runs on,
  // 1.3 GiB at 3200 x 1800 against 7.3 GiB for an 8K frame.
  int max_image_size = 3200;
  void Check() const;
};

// The grey image SIFT runs on: the frame resized by `upscale`, or down to `max_image_size`,
// with its size over the frame's along each axis.
struct SiftInput {
  cv::Mat grey;
  double scale_x = 1.0;
  double scale_y = 1.0;
};

// Makes the SIFT input of an 8-bit grey or BGR image. The input is all that detection needs,
// so a caller can let go of a large frame once it has it.
SiftInput PrepareSiftInput(const cv::Mat& image, const SiftOptions& options);

// Extracts SIFT features from a prepared input, keypoints in the frame's pixels.
FeatureSet ExtractSift(const SiftInput& input, const SiftOptions& options);

// Extracts SIFT features from an 8-bit grey or BGR image. Single-threaded per call; run
// frames in parallel from the caller. Also returns the BGR colour under each keypoint in
// `colors` when it is non-null (used for coloured point clouds).
FeatureSet ExtractSift(const cv::Mat& image, const SiftOptions& options,
                       std::vector<Eigen::Matrix<uint8_t, 3, 1>>* colors = nullptr);

// Normalises float descriptors in place (L2, or RootSIFT) and quantises them like COLMAP.
FeatureDescriptors QuantizeDescriptors(const cv::Mat& float_descriptors, bool root_sift);

}  // namespace loopsfm
