#pragma once
// Self-calibration before mapping: for every camera without a prior focal length (no
// --intrinsics), one focal length shared by all its frames is estimated from the fundamental
// matrices of its verified uncalibrated pairs (estimators/focal_estimation.h: the f that
// makes K^T F K an essential matrix, by a robust vote over the pairs), with the principal
// point at the image centre. The camera takes the estimate, and the relative poses of the
// camera's pairs are re-estimated with it (matching/geometric_verification.h,
// UpdateRelativePose), so the initial pair ranking and the first two-view model rest on the
// estimate, not on the guess of 1.2 x the image size. Global bundle adjustments refine it
// further (IncrementalMapperOptions::refine_unknown).
//
// When the estimate fails (too few pairs with a clear minimum, a wide spread, or f at the end
// of the search range: e.g. a video that only walks straight ahead), the camera keeps its
// guess and the report says why; the mapper then relies on bundle adjustment alone.

#include <string>
#include <vector>

#include "loopsfm/estimators/focal_estimation.h"
#include "loopsfm/matching/geometric_verification.h"
#include "loopsfm/sfm/mapper_input.h"

namespace loopsfm {

struct SelfCalibrationOptions {
  FocalEstimationOptions focal;
  // Thresholds of the relative poses re-estimated with the new focal length (max_error,
  // min_planar_tri_angle_deg); the same as matching's.
  TwoViewVerificationOptions verification;
  // Pairs of a camera used for its estimate, at most: those with the most inliers (the
  // vote costs a few microseconds per pair and grid sample).
  int max_num_pairs = 3000;
  void Check() const;
};

struct CameraSelfCalibration {
  camera_t camera_id = kInvalidCameraId;
  // The focal length before (the guess) and after (the estimate when applied).
  double initial_focal_px = 0.0;
  double focal_px = 0.0;
  // Whether the camera took the estimate.
  bool applied = false;
  FocalEstimate estimate;
};

struct SelfCalibrationReport {
  std::vector<CameraSelfCalibration> cameras;
  // Pairs whose relative pose was re-estimated.
  size_t num_pairs_updated = 0;
  double seconds = 0.0;
};

// Estimates and applies the focal length of every camera of `input` without a prior; the
// cameras keep has_prior_focal_length false (bundle adjustment still refines them).
SelfCalibrationReport SelfCalibrate(const SelfCalibrationOptions& options, MapperInput* input);

}  // namespace loopsfm
