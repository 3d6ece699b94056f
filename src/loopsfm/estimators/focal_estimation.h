#pragma once
// Self-calibration of one focal length shared by all images of a video, from the fundamental
// matrices of verified image pairs (before any mapping).
//
// Model. A pinhole camera with square pixels, a known principal point (the image centre for
// a phone video) and an unknown focal length f in pixels, the same camera in both views of
// every pair. For the right f and K = [[f, 0, cx], [0, f, cy], [0, 0, 1]], E(f) = K^T F K is
// an essential matrix: its two non-zero singular values are equal (Mendonca & Cipolla 1999,
// "A simple technique for self-calibration"). The cost of a pair at f is
//
//     c(f) = (s1 - s2) / (s1 + s2)    with s1 >= s2 the largest singular values of E(f),
//
// which is 0 for an essential matrix, at most 1, and does not depend on the scale of F.
//
// Method (EstimateSharedFocalLength).
//   1. Every pair's cost is sampled on a log-spaced grid of f in
//      [min_focal_factor, max_focal_factor] x max(width, height).
//   2. A pair is used only when its curve has one clear minimum: inside the grid, at most
//      max_pair_cost, rising on both sides by min_cost_rise (and by min_cost_rise_ratio
//      times the minimum), with no second local minimum nearly as deep more than
//      ambiguity_log_distance away. Its minimum, refined by golden-section search, is the
//      pair's own estimate of f.
//   3. Robust vote: the grid sample with the largest weighted (e.g. by inlier counts) sum of
//      Epanechnikov kernels of width inlier_log_tolerance over the pairs' estimates (in log
//      f), moved by mean shift to the local weighted mean. Wrong pairs, pairs of another
//      camera and badly conditioned ones scatter, or gather elsewhere with less weight.
//   4. Inliers: used pairs whose estimate is within inlier_log_tolerance of the vote and whose
//      cost there is at most max_pair_cost. f is the weighted interquartile mean (the mean
//      of the middle half of the weight) of the inliers' estimates; the inliers are counted
//      again at that f.
//   5. spread: 1.4826 x the weighted median of |log(f_pair / f)| over all used pairs, a robust
//      standard deviation of the per-pair estimates relative to f.
//   Minimising the summed (squared or truncated) costs over f instead was less accurate: a
//   pair whose F fits badly but whose curve is steep pulls the sum towards its own minimum.
//
// Accuracy (focal_estimation_test, 100 random problems: 50 pairs of 200 matches with 0.5 px
// noise, F by the normalised 8-point algorithm, f = 0.5 .. 3 x 1920 on 1920 x 1080, turning
// 10-40 degrees): median relative error of f 0.06 % (max 0.32 %); with 30 % outlier pairs
// (F of random matches, of another focal length, of pure rotations) 0.08 % (max 0.38 %).
//
// When it fails or is ill-conditioned. From F alone, f is not observable when the views do
// not turn (pure translation, e.g. walking straight ahead), turn about the optical axis only,
// or orbit a point while keeping it centred (optical axes meeting at equal distances from
// both cameras); f is badly conditioned near these cases, and each pair's estimate is less
// precise for long focal lengths (little perspective) and small rotations. Such pairs give
// flat cost curves and are not used. F of wrong matches or of ill-conditioned scenes (tiny
// baselines with noise, planar scenes where F is not unique) have no clear minimum or one
// at a random f, and count as outliers; when all pairs are planar their estimates scatter
// by 10-40 % (max_spread). When fewer than min_num_pairs pairs are usable, when the inliers
// are too few, when the estimates scatter, or when f lies at the end of the search range,
// success is false and explanation says why.
//
// Pure rotations are not degenerate here: an F fitted to a pure rotation (x2 = K R K^-1 x1)
// is a member of the family (K R K^-1)^-T [v]x, and every member is a valid fundamental
// matrix of the true K (with translation direction K^-1 v), so such pairs vote for the true
// f (focal_estimation_test checks it).

#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace loopsfm {

struct FocalEstimationOptions {
  // Search range of f as multiples of max(width, height): 0.3 is a 118 degree field of view
  // across the long side, 5 is 11 degrees.
  double min_focal_factor = 0.3;
  double max_focal_factor = 5.0;
  // Samples of the log-spaced search grid (256 over 0.3 .. 5: 1.1 % apart).
  int num_grid_samples = 256;
  // Largest cost (s1 - s2) / (s1 + s2) of a used pair at its minimum, and of an inlier at the
  // estimate. 0.5 px noise gives about 0.0001 .. 0.01; F of random matches about 0.9.
  double max_pair_cost = 0.05;
  // A pair's curve must rise by at least this much on both sides of its minimum, within the
  // search range, to be used (absolute, in cost units) ...
  double min_cost_rise = 0.02;
  // ... and by at least this many times its minimum cost.
  double min_cost_rise_ratio = 2.0;
  // A second local minimum farther than this (in |log f|) from the best, whose cost is below
  // the best's plus half its rise, makes the pair ambiguous: it is not used.
  double ambiguity_log_distance = 0.1;
  // Width of the vote's kernel, and a used pair is an inlier when its own estimate is within
  // this of f (in |log f|, so 0.05 is about 5 %).
  double inlier_log_tolerance = 0.05;
  // Fewest used pairs, and fewest inlier pairs, for a successful estimate.
  int min_num_pairs = 5;
  // Fewest inliers as a fraction of the used pairs.
  double min_inlier_ratio = 0.3;
  // Largest spread (robust relative standard deviation of the used pairs' estimates) of a
  // successful estimate. Measured: 0.3-2.5 % with 0.5 px noise, 1.6-3.6 % with 2 px, up to
  // 5 % for rotations of 1-3 degrees with 1 px noise, 12-43 % when all pairs see one plane.
  double max_spread = 0.1;
  // The golden-section search of each pair's minimum stops when the bracket is this small
  // (relative, in f).
  double refine_tolerance = 1e-7;
  void Check() const;  // throws loopsfm::InvalidArgument
};

struct FocalEstimate {
  // True when f was found with enough consistent pairs (see the conditions above).
  bool success = false;
  // The shared focal length in pixels: the best estimate, also when success is false, if at
  // least min_num_pairs pairs were usable; 0 otherwise.
  double focal_px = 0.0;
  // Robust relative standard deviation of the used pairs' own estimates around f
  // (0.01 = 1 %), weighted; see step 5 above.
  double spread = 0.0;
  // Pairs given, pairs whose cost curve had one clear minimum, and inliers among those.
  int num_pairs = 0;
  int num_pairs_used = 0;
  int num_pairs_inlier = 0;
  // Per pair: its own estimate of f in pixels (0 when its curve had no clear minimum) and
  // whether it is an inlier.
  std::vector<double> pair_focal_px;
  std::vector<char> pair_is_inlier;
  // Why success is false (empty on success).
  std::string explanation;
};

// The singular-value cost (s1 - s2) / (s1 + s2) of E = K^T F K for the focal length
// focal_px and the principal point; 1 when F is zero or not finite.
double EssentialSingularValueCost(const Eigen::Matrix3d& fundamental_matrix,
                                  const Eigen::Vector2d& principal_point, double focal_px);

// fundamental_matrices: one per verified pair, in pixels (COLMAP convention: x2^T F x1 = 0
// with x = (column + 0.5, row + 0.5)-style pixel coordinates, the same as principal_point).
// weights: one per pair (e.g. its number of inlier matches), >= 0, or empty for equal
// weights; pairs of weight 0 are ignored. width, height: image size in pixels, > 0.
// Throws loopsfm::InvalidArgument on bad options, sizes or weights.
FocalEstimate EstimateSharedFocalLength(std::span<const Eigen::Matrix3d> fundamental_matrices,
                                        std::span<const double> weights,
                                        const Eigen::Vector2d& principal_point, int width,
                                        int height, const FocalEstimationOptions& options);

}  // namespace loopsfm
