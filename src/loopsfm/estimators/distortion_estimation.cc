#include "loopsfm/estimators/distortion_estimation.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <utility>

#include <fmt/format.h>

#include "loopsfm/geometry/epipolar.h"
#include "loopsfm/math/golden_section.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// The largest undistorted radius (units of s) where r + kappa r^3 still grows; infinite for
// kappa >= 0.
double FoldOverRadius(double kappa) {
  return kappa < 0.0 ? std::sqrt(-1.0 / (3.0 * kappa)) : std::numeric_limits<double>::infinity();
}

// Median image motion |y - x| of a pair's correspondences.
double MedianMotion(const PairCorrespondences& pair) {
  std::vector<double> motion;
  motion.reserve(pair.points1.size());
  for (size_t i = 0; i < pair.points1.size(); ++i) {
    motion.push_back((pair.points2[i] - pair.points1[i]).norm());
  }
  if (motion.empty()) return 0.0;
  std::nth_element(motion.begin(), motion.begin() + motion.size() / 2, motion.end());
  return motion[motion.size() / 2];
}

// Both sides of a pair undistorted under kappa (points beyond the fold-over dropped); the
// kept points' indices in `kept` when given.
void UndistortPair(const PairCorrespondences& pair, const Eigen::Vector2d& principal_point,
                   double radius_unit, double kappa, PairCorrespondences* undistorted,
                   std::vector<size_t>* kept = nullptr) {
  undistorted->points1.clear();
  undistorted->points2.clear();
  if (kept) kept->clear();
  for (size_t i = 0; i < pair.points1.size(); ++i) {
    Eigen::Vector2d a, b;
    if (UndistortRadialPixel(pair.points1[i], principal_point, radius_unit, kappa, &a) &&
        UndistortRadialPixel(pair.points2[i], principal_point, radius_unit, kappa, &b)) {
      undistorted->points1.push_back(a);
      undistorted->points2.push_back(b);
      if (kept) kept->push_back(i);
    }
  }
}

// The fundamental matrix of a pair's (undistorted) points by the eight-point algorithm,
// refitted a few times to the points whose Sampson distance to it is below cap2 (squared
// pixels), so that a wrong match does not tilt it for all the others. Least squares alone
// bends F towards every wrong match; refitting to a fixed fraction instead (least trimmed
// squares) was tried and biased kappa: the points a wrong kappa fits worst are the ones
// near the image border, and dropping them rewards the wrong kappa (measured: k -0.157 for
// -0.12, and 0.027 for a lens without distortion).
Eigen::Matrix3d FitFundamental(const PairCorrespondences& pair, double cap2) {
  constexpr int kRefits = 3;
  Eigen::Matrix3d F = FundamentalFromEightPoints(pair.points1, pair.points2);
  std::vector<Eigen::Vector2d> kept1, kept2;
  for (int refit = 0; refit < kRefits && !F.isZero(0.0); ++refit) {
    kept1.clear();
    kept2.clear();
    for (size_t i = 0; i < pair.points1.size(); ++i) {
      if (SampsonSquaredError(F, pair.points1[i], pair.points2[i]) < cap2) {
        kept1.push_back(pair.points1[i]);
        kept2.push_back(pair.points2[i]);
      }
    }
    if (kept1.size() == pair.points1.size() || kept1.size() < 8) break;
    const Eigen::Matrix3d refitted = FundamentalFromEightPoints(kept1, kept2);
    if (refitted.isZero(0.0)) break;
    F = refitted;
  }
  return F;
}

// The capped squared Sampson distance of every point of every pair under kappa, in order (a
// point dropped by the undistortion, or any point of a pair that could not be fitted, has
// the cap).
std::vector<double> ErrorsAt(std::span<const PairCorrespondences> pairs,
                             const Eigen::Vector2d& principal_point, double radius_unit,
                             double kappa, double cap) {
  const double cap2 = cap * cap;
  std::vector<double> errors;
  PairCorrespondences undistorted;
  std::vector<size_t> index;
  for (const PairCorrespondences& pair : pairs) {
    const size_t first = errors.size();
    errors.resize(first + pair.points1.size(), cap2);
    UndistortPair(pair, principal_point, radius_unit, kappa, &undistorted, &index);
    const Eigen::Matrix3d F = FitFundamental(undistorted, cap2);
    if (F.isZero(0.0)) continue;
    for (size_t j = 0; j < index.size(); ++j) {
      errors[first + index[j]] = std::min(
          SampsonSquaredError(F, undistorted.points1[j], undistorted.points2[j]), cap2);
    }
  }
  return errors;
}

// RMS of the errors where mask is empty or true.
double MaskedRms(const std::vector<double>& errors, const std::vector<char>& mask) {
  double sum = 0.0;
  size_t count = 0;
  for (size_t i = 0; i < errors.size(); ++i) {
    if (!mask.empty() && !mask[i]) continue;
    sum += errors[i];
    ++count;
  }
  return count > 0 ? std::sqrt(sum / static_cast<double>(count)) : 0.0;
}

}  // namespace

void RadialDistortionOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_kappa > -4.0 / 27.0 && min_kappa < max_kappa && std::isfinite(max_kappa),
                         "radial distortion search: need -4/27 < min_kappa < max_kappa, got {} and {}",
                         min_kappa, max_kappa);
  LOOPSFM_REQUIRE_OPTION(num_grid_samples >= 3 && num_grid_samples <= 10000,
                         "radial distortion search: num_grid_samples must be in [3, 10000], got {}",
                         num_grid_samples);
  LOOPSFM_REQUIRE_OPTION(refine_tolerance > 0, "radial distortion search: refine_tolerance must "
                         "be positive, got {}", refine_tolerance);
  LOOPSFM_REQUIRE_OPTION(error_cap_px > 0, "radial distortion search: error_cap_px must be "
                         "positive, got {}", error_cap_px);
  LOOPSFM_REQUIRE_OPTION(min_error_drop >= 0 && min_error_drop < 1, "radial distortion search: "
                         "min_error_drop must be in [0, 1), got {}", min_error_drop);
  LOOPSFM_REQUIRE_OPTION(max_num_pairs >= min_num_pairs && min_num_pairs >= 1,
                         "radial distortion search: need 1 <= min_num_pairs <= max_num_pairs, "
                         "got {} and {}", min_num_pairs, max_num_pairs);
  LOOPSFM_REQUIRE_OPTION(min_pair_points >= 8, "radial distortion search: min_pair_points must be "
                         "at least 8, got {}", min_pair_points);
}

double DistortionRadiusUnit(int width, int height) {
  return 0.5 * std::hypot(static_cast<double>(width), static_cast<double>(height));
}

bool UndistortRadialPixel(const Eigen::Vector2d& distorted, const Eigen::Vector2d& principal_point,
                          double radius_unit, double kappa, Eigen::Vector2d* undistorted) {
  const Eigen::Vector2d offset = (distorted - principal_point) / radius_unit;
  const double rd = offset.norm();
  if (kappa == 0.0 || rd == 0.0) {
    *undistorted = distorted;
    return true;
  }
  // Solve g(r) = r + kappa r^3 - rd = 0 on [0, r_max], where g grows: Newton, kept inside
  // the bracket that bisection would keep.
  double lo = 0.0, hi = FoldOverRadius(kappa);
  if (std::isfinite(hi) && hi + kappa * hi * hi * hi < rd) return false;
  if (!std::isfinite(hi)) hi = rd;  // kappa > 0: r <= rd
  double r = std::min(rd, hi);
  for (int iteration = 0; iteration < 50; ++iteration) {
    const double g = r + kappa * r * r * r - rd;
    if (g > 0.0) hi = r; else lo = r;
    const double slope = 1.0 + 3.0 * kappa * r * r;
    double next = slope > 0.0 ? r - g / slope : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - r) <= 1e-14 * std::max(1.0, r)) {
      r = next;
      break;
    }
    r = next;
  }
  *undistorted = principal_point + offset * (r / rd * radius_unit);
  return true;
}

double RadialTermForFocalLength(double kappa, double focal_px, double radius_unit) {
  const double ratio = focal_px / radius_unit;
  return kappa * ratio * ratio;
}

std::vector<Eigen::Matrix3d> UndistortedFundamentals(std::span<const PairCorrespondences> pairs,
                                                     const Eigen::Vector2d& principal_point,
                                                     double radius_unit, double kappa,
                                                     double error_cap_px) {
  std::vector<Eigen::Matrix3d> fundamentals;
  fundamentals.reserve(pairs.size());
  PairCorrespondences undistorted;
  for (const PairCorrespondences& pair : pairs) {
    UndistortPair(pair, principal_point, radius_unit, kappa, &undistorted);
    fundamentals.push_back(FitFundamental(undistorted, error_cap_px * error_cap_px));
  }
  return fundamentals;
}

RadialDistortionEstimate EstimateRadialDistortion(std::span<const PairCorrespondences> pairs,
                                                  const Eigen::Vector2d& principal_point,
                                                  int width, int height,
                                                  const RadialDistortionOptions& options) {
  options.Check();
  LOOPSFM_REQUIRE_OPTION(width > 0 && height > 0, "radial distortion search: image size must be "
                         "positive, got {}x{}", width, height);
  for (const PairCorrespondences& pair : pairs) {
    LOOPSFM_REQUIRE_OPTION(pair.points1.size() == pair.points2.size(), "radial distortion search: "
                           "a pair has {} points in one image and {} in the other",
                           pair.points1.size(), pair.points2.size());
  }
  RadialDistortionEstimate estimate;

  // The pairs whose points move most.
  std::vector<std::pair<double, size_t>> by_motion;
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (static_cast<int>(pairs[i].points1.size()) >= options.min_pair_points) {
      by_motion.emplace_back(MedianMotion(pairs[i]), i);
    }
  }
  std::sort(by_motion.begin(), by_motion.end(), std::greater<>());
  if (by_motion.size() > static_cast<size_t>(options.max_num_pairs)) {
    by_motion.resize(options.max_num_pairs);
  }
  std::vector<PairCorrespondences> used;
  used.reserve(by_motion.size());
  for (const auto& [motion, index] : by_motion) used.push_back(pairs[index]);
  estimate.num_pairs_used = static_cast<int>(used.size());
  if (estimate.num_pairs_used < options.min_num_pairs) {
    estimate.explanation = fmt::format("only {} pairs with {} or more correspondences (needs {})",
                                       estimate.num_pairs_used, options.min_pair_points,
                                       options.min_num_pairs);
    return estimate;
  }

  const double unit = DistortionRadiusUnit(width, height);
  auto error_at = [&](double kappa) {
    return MaskedRms(ErrorsAt(used, principal_point, unit, kappa, options.error_cap_px), {});
  };
  const int n = options.num_grid_samples;
  const double step = (options.max_kappa - options.min_kappa) / (n - 1);
  int best = 0;
  double best_error = std::numeric_limits<double>::infinity();
  for (int i = 0; i < n; ++i) {
    const double error = error_at(options.min_kappa + i * step);
    if (error < best_error) {
      best_error = error;
      best = i;
    }
  }
  const double lo = options.min_kappa + std::max(best - 1, 0) * step;
  const double hi = options.min_kappa + std::min(best + 1, n - 1) * step;
  estimate.kappa = GoldenSectionMinimum(error_at, lo, hi, options.refine_tolerance);
  std::vector<double> at_estimate =
      ErrorsAt(used, principal_point, unit, estimate.kappa, options.error_cap_px);
  if (best_error < MaskedRms(at_estimate, {})) {  // the refinement found a worse local minimum
    estimate.kappa = options.min_kappa + best * step;
    at_estimate = ErrorsAt(used, principal_point, unit, estimate.kappa, options.error_cap_px);
  }
  // Significance on the points that fit at the estimate: a wrong match is capped whatever
  // kappa is, and counted it would only dilute the fall (10 random matches among 150 per
  // pair: 4 % instead of about 50 %).
  const double cap2 = options.error_cap_px * options.error_cap_px;
  std::vector<char> fits(at_estimate.size());
  for (size_t i = 0; i < at_estimate.size(); ++i) fits[i] = at_estimate[i] < cap2;
  estimate.error_px = MaskedRms(at_estimate, fits);
  estimate.error_px_without =
      MaskedRms(ErrorsAt(used, principal_point, unit, 0.0, options.error_cap_px), fits);
  const double drop = estimate.error_px_without > 0.0
                          ? 1.0 - estimate.error_px / estimate.error_px_without
                          : 0.0;
  estimate.significant = drop >= options.min_error_drop;
  if (!estimate.significant) {
    estimate.explanation = fmt::format(
        "undistorting with kappa {:.4f} lowers the epipolar error only from {:.3f} to {:.3f} px "
        "({:.1f} %, needs {:.0f} %)", estimate.kappa, estimate.error_px_without,
        estimate.error_px, 100.0 * drop, 100.0 * options.min_error_drop);
  }
  return estimate;
}

}  // namespace loopsfm
