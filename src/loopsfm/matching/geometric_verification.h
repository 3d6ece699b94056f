#pragma once
// Geometric verification of the raw matches of an image pair (COLMAP's two-view geometry).
//
// Estimates with OpenCV's USAC (LO-RANSAC, MSAC scoring):
//   - the fundamental matrix F and the homography H on the pixel coordinates (F only when E
//     leaves it a chance: see num_F_inliers);
//   - the essential matrix E on normalised, undistorted coordinates (Camera::CamFromImg) when
//     both cameras have a prior focal length, with threshold max_error / mean focal length;
// and classifies the pair as COLMAP does: kCalibrated (E explains nearly as many matches as
// F), kUncalibrated (F only), kPlanar / kPanoramic (H explains most of the E or F inliers),
// or kDegenerate (too few inliers, or too small a fraction of the matches).
//
// OpenCV 4.6's USAC returns the model of its best local optimisation on a small inlier sample
// and has no final polishing, so: F is refitted by the 8-point algorithm on all its inliers;
// the pose of E is polished by Levenberg-Marquardt on the Sampson errors of its inliers
// (relative_pose_refinement.h) and E's inliers re-selected with it. Inliers of E and F are
// both counted by Sampson error, so that the E / F comparison is fair.
//
// The relative pose cam2_from_cam1 (x_cam2 = R x_cam1 + t) comes from E (decomposition with
// cheirality, then polished); for uncalibrated pairs from E = K2^T F K1 with the cameras'
// guessed intrinsics, polished on F's inliers (as COLMAP, a rough pose when the guess is
// wrong; to re-estimate an initial pair as calibrated, pass cameras with
// has_prior_focal_length set); for planar pairs from the decomposition of H with the most
// matches in front of both cameras.
//
// Determinism: OpenCV's USAC takes its random seed in cv::UsacParams::randomGeneratorState,
// so no global state (cv::theRNG) is touched; the seeds are drawn from the Random passed in.
// Give each pair its own generator (e.g. Random::Derive(PairToPairId(pair))) and the result
// does not depend on thread count or scheduling. USAC runs single-threaded (isParallel off).

#include <optional>
#include <vector>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/camera.h"
#include "loopsfm/scene/features.h"
#include "loopsfm/scene/two_view_geometry.h"

namespace loopsfm {

struct TwoViewVerificationOptions {
  // Largest epipolar (Sampson) or homography transfer error of an inlier, in pixels.
  double max_error = 4.0;
  // Probability that RANSAC has found the best model when it stops early.
  double confidence = 0.999;
  // Most RANSAC iterations per model (E, F and H each).
  int max_num_trials = 10000;
  // Pairs with fewer inliers than this are rejected (kDegenerate). At least 8.
  int min_num_inliers = 15;
  // Pairs whose inliers are a smaller fraction of the raw matches are rejected (kDegenerate).
  double min_inlier_ratio = 0.1;
  // A pair with intrinsics is kCalibrated when E has at least this fraction of F's inliers.
  double min_E_F_inlier_ratio = 0.95;
  // A pair is planar or panoramic when H has more than this fraction of E's (or F's) inliers.
  double max_H_inlier_ratio = 0.8;
  // A planar-or-panoramic pair whose median ray angle is below this is kPanoramic (pure
  // rotation), otherwise kPlanar; in degrees.
  double min_planar_tri_angle_deg = 0.5;

  // Throws loopsfm::InvalidArgument with a readable message.
  void Check() const;
};

struct TwoViewVerification {
  // Configuration, E / F / H, relative pose and the inlier matches of the chosen model.
  TwoViewGeometry geometry;
  // Number of raw matches given.
  int num_matches = 0;
  // Inliers of each model. num_E_inliers is 0 when E was not estimated (no intrinsics);
  // num_F_inliers is 0 when F was not needed: E's inliers are at least min_E_F_inlier_ratio
  // of all matches, so no F could make the pair uncalibrated (geometry.F then comes from E).
  int num_E_inliers = 0;
  int num_F_inliers = 0;
  int num_H_inliers = 0;
  // num_H_inliers over the inliers of the epipolar model (E when calibrated, else F); high
  // for planar scenes and pure rotations, which make poor initial pairs. 0 when undefined.
  double h_inlier_ratio = 0.0;
  // Median angle, in degrees, between the two viewing rays of the inlier matches under the
  // recovered rotation (the triangulation angle for exact matches); 0 when no pose.
  double median_tri_angle_deg = 0.0;
  // Inlier matches in front of both cameras for the recovered pose (cheirality); 0 for
  // kPanoramic pairs, which have no baseline to triangulate with.
  int num_pose_inliers = 0;
};

// Verifies `matches` between keypoints1 (image 1, taken with camera1) and keypoints2 (image 2,
// camera2). Keypoints are in COLMAP's pixel convention. geometry.cam2_from_cam1 has a unit
// translation, except for kPanoramic pairs where it is zero. Rejected pairs have config
// kDegenerate and no inlier matches. Throws InputError when a match indexes a keypoint that
// does not exist.
TwoViewVerification VerifyTwoViewGeometry(const Camera& camera1,
                                          const FeatureKeypoints& keypoints1,
                                          const Camera& camera2,
                                          const FeatureKeypoints& keypoints2,
                                          const FeatureMatches& matches,
                                          const TwoViewVerificationOptions& options,
                                          Random& random);

// Re-estimates E and the relative pose of a verified uncalibrated, planar or panoramic pair
// from its F or H and its inlier matches under new intrinsics (after self-calibration has
// replaced a guessed focal length), as VerifyTwoViewGeometry would have with them; a planar
// pair may become panoramic and back. keypoints1/2: the two images' keypoint positions
// (pixels), indexed by the inlier matches. Other pairs are left unchanged.
void UpdateRelativePose(const Camera& camera1, const std::vector<Eigen::Vector2d>& keypoints1,
                        const Camera& camera2, const std::vector<Eigen::Vector2d>& keypoints2,
                        const TwoViewVerificationOptions& options, TwoViewGeometry* geometry);

// The relative pose a verified pair's F gives under the cameras' intrinsics (the essential
// matrix's pose, refined on the inliers' Sampson errors), whatever its configuration. A
// planar pair's pose from its homography can pick the wrong one of the decomposition's
// solutions where the baseline is short; its F still holds the rotation. Returns nullopt
// for a pair without an F.
std::optional<Rigid3d> EssentialPoseOfPair(const Camera& camera1,
                                           const std::vector<Eigen::Vector2d>& keypoints1,
                                           const Camera& camera2,
                                           const std::vector<Eigen::Vector2d>& keypoints2,
                                           const TwoViewVerificationOptions& options,
                                           const TwoViewGeometry& geometry);

}  // namespace loopsfm
