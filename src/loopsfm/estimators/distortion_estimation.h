#pragma once
// Self-calibration of one radial distortion term shared by all images of a camera, from the
// point correspondences of its verified image pairs (before any mapping), so that a lens that
// bends straight lines (an action camera, a wide phone lens) does not throw off the focal
// length estimated from fundamental matrices (focal_estimation.h): the pairs' F, fitted to
// distorted points, otherwise vote for focal lengths that scatter and miss (docs/benchmarks.md,
// "Intrinsics and self-calibration").
//
// Model. SIMPLE_RADIAL's radial term in pixels about the principal point c, in units of s =
// half the image diagonal:
//
//     x_d - c = (x_u - c) (1 + kappa |x_u - c|^2 / s^2),
//
// so kappa is the relative radial displacement at the image corner, and for a focal length f
// SIMPLE_RADIAL's k = kappa (f / s)^2 (RadialTermForFocalLength). kappa needs no f.
//
// Method (EstimateRadialDistortion). A pair's correspondences obey one fundamental matrix
// only once they are undistorted with the right kappa. For each kappa of a grid over
// [min_kappa, max_kappa], every pair's points are undistorted (about c, with s), a
// fundamental matrix is fitted to them by the normalised eight-point algorithm (refitted
// up to three times to the points within error_cap_px of it, so that a wrong match does not
// tilt it), and the squared Sampson distances (pixels, capped at error_cap_px so that a
// wrong match cannot dominate) are summed over all points of all pairs. The grid's best
// kappa, refined by golden-section search between its neighbours, is the estimate; error_px
// is the RMS distance there of the points within error_cap_px of their pair's F, and
// error_px_without the RMS of the same points at kappa = 0. Fitzgibbon (CVPR 2001) estimates F and a
// division-model term together from 9 points; this searches the polynomial term the bundle
// adjustment refines instead, so that nothing needs converting.
//
// The estimate is significant when the error falls by at least min_error_drop (relative)
// against kappa = 0: a lens without distortion gives a curve whose minimum is near 0 and
// hardly lower than the value there (noise fitted), and the caller then keeps k = 0.
//
// Pairs that move little (neighbouring video frames) say little about kappa: their points
// keep their place in the image, so their distortion cancels. The pairs whose points move
// most (median image motion) are used, at most max_num_pairs.

#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace loopsfm {

struct RadialDistortionOptions {
  // Search range of kappa. The polynomial folds over inside the image corner below -4/27
  // (-0.148): radii past its maximum cannot be undistorted.
  double min_kappa = -0.14;
  double max_kappa = 0.3;
  // Grid samples over the range (0.02 apart by default); the best is then refined to
  // refine_tolerance.
  int num_grid_samples = 23;
  double refine_tolerance = 1e-4;
  // Sampson distances are capped here (pixels) before they are summed.
  double error_cap_px = 4.0;
  // Smallest relative fall of the RMS error against kappa = 0 for a significant estimate.
  // Measured on video and photos without distortion: 1.5 % (fox, a phone), 1.6 %
  // (templeRing), 1.8 % (kitti07_160, rectified); with it (rendered, H.264): 9.6 % (480x270,
  // f 432 px, k1 -0.12: 12 px at the corners), 29 % (96 degrees, k1 -0.07), 62 % (k1 -0.085).
  double min_error_drop = 0.05;
  // Pairs used, at most (those whose points move most), and the fewest: fewer usable pairs
  // (with at least min_pair_points correspondences) give no estimate.
  int max_num_pairs = 300;
  int min_num_pairs = 5;
  int min_pair_points = 16;
  void Check() const;  // throws loopsfm::InvalidArgument
};

// The inlier correspondences of one image pair, in pixels (x_i of image 1 matches y_i of
// image 2).
struct PairCorrespondences {
  std::vector<Eigen::Vector2d> points1, points2;
};

struct RadialDistortionEstimate {
  // True when the estimate is significant (see above); kappa is then the estimate, otherwise
  // the best kappa found (0 when there were too few pairs).
  bool significant = false;
  double kappa = 0.0;
  // RMS Sampson distance (pixels) at kappa of the points that fit there (within
  // error_cap_px), and of the same points at 0.
  double error_px = 0.0;
  double error_px_without = 0.0;
  int num_pairs_used = 0;
  // Why the estimate is not significant (empty when it is).
  std::string explanation;
};

// Half the diagonal of a width x height image: the unit of kappa's radius.
double DistortionRadiusUnit(int width, int height);

// The undistorted pixel of a distorted one under kappa (see the model above); false where the
// radius lies beyond what the polynomial reaches (a fold-over).
bool UndistortRadialPixel(const Eigen::Vector2d& distorted, const Eigen::Vector2d& principal_point,
                          double radius_unit, double kappa, Eigen::Vector2d* undistorted);

// SIMPLE_RADIAL's k (normalised image coordinates) for kappa and a focal length in pixels.
double RadialTermForFocalLength(double kappa, double focal_px, double radius_unit);

// Throws loopsfm::InvalidArgument on bad options or sizes.
RadialDistortionEstimate EstimateRadialDistortion(std::span<const PairCorrespondences> pairs,
                                                  const Eigen::Vector2d& principal_point,
                                                  int width, int height,
                                                  const RadialDistortionOptions& options);

// The fundamental matrix of each pair's correspondences undistorted under kappa (pixels), by
// the eight-point fit above (refitted to the points within error_cap_px); zero for a pair it
// cannot fit.
std::vector<Eigen::Matrix3d> UndistortedFundamentals(std::span<const PairCorrespondences> pairs,
                                                     const Eigen::Vector2d& principal_point,
                                                     double radius_unit, double kappa,
                                                     double error_cap_px);

}  // namespace loopsfm
