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
// Lens distortion first. For a camera whose model has a polynomial radial term k1
// (SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV), one radial term is estimated before the focal
// length from the pairs' inlier correspondences (estimators/distortion_estimation.h: the
// kappa that lets each pair's undistorted points fit one fundamental matrix best). When it is
// significant, the focal length is estimated from the fundamental matrices of the undistorted
// points instead of the verified F, and the camera starts with k1 = kappa (f / s)^2. A wide
// barrel lens biases the verified F: on rendered 96 degree streets (f 288 px) they voted for
// 326 px with a 7.7 % spread (k1 -0.07) and scattered too much for any estimate (k1 -0.085);
// undistorted, 294.7 px with k1 -0.068 and 292.4 px with k1 -0.084. Fisheye and
// distortion-free models skip this step.
//
// When the estimate fails (too few pairs with a clear minimum, a wide spread, or f at the end
// of the search range: e.g. a video that only walks straight ahead), the camera keeps its
// guess and the report says why; the mapper then relies on bundle adjustment alone. A
// significant distortion estimate is applied only with a focal length (k1 depends on it).

#include <string>
#include <vector>

#include "loopsfm/estimators/distortion_estimation.h"
#include "loopsfm/estimators/focal_estimation.h"
#include "loopsfm/matching/geometric_verification.h"
#include "loopsfm/sfm/mapper_input.h"

namespace loopsfm {

struct SelfCalibrationOptions {
  FocalEstimationOptions focal;
  // Estimate a radial term before the focal length (see above), for models that have one.
  bool estimate_distortion = true;
  RadialDistortionOptions distortion;
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
  // Whether the radial term was estimated (the model has one and estimate_distortion), the
  // estimate, and the k1 the camera took (0 when the estimate was not significant or no
  // focal length was applied).
  bool distortion_estimated = false;
  RadialDistortionEstimate distortion;
  double k1 = 0.0;
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
