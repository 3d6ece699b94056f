#include "loopsfm/estimators/focal_estimation.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <Eigen/SVD>
#include <fmt/format.h>

#include "loopsfm/math/golden_section.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// F in coordinates centred on the principal point and divided by `scale`, with unit
// Frobenius norm: pixel x = T S y with T the shift to the principal point and
// S = diag(scale, scale, 1), so y2^T (S T^T F T S) y1 = 0. Then E(f) = D G D with
// D = diag(f / scale, f / scale, 1). False when F is zero or not finite.
bool NormaliseFundamental(const Eigen::Matrix3d& fundamental,
                          const Eigen::Vector2d& principal_point, double scale,
                          Eigen::Matrix3d* normalised) {
  if (!fundamental.allFinite()) return false;
  Eigen::Matrix3d from_normalised = Eigen::Matrix3d::Identity();
  from_normalised(0, 0) = scale;
  from_normalised(1, 1) = scale;
  from_normalised(0, 2) = principal_point.x();
  from_normalised(1, 2) = principal_point.y();
  Eigen::Matrix3d g = from_normalised.transpose() * fundamental * from_normalised;
  const double norm = g.norm();
  if (!(norm > 0.0) || !std::isfinite(norm)) return false;
  *normalised = g / norm;
  return true;
}

// (s1 - s2) / (s1 + s2) of D G D, D = diag(g, g, 1).
double NormalisedCost(const Eigen::Matrix3d& normalised, double g) {
  Eigen::Matrix3d essential = normalised;
  essential.topRows<2>() *= g;
  essential.leftCols<2>() *= g;
  const Eigen::Vector3d s = Eigen::JacobiSVD<Eigen::Matrix3d>(essential).singularValues();
  const double sum = s[0] + s[1];
  return sum > 0.0 ? (s[0] - s[1]) / sum : 1.0;
}

// Index of the clear minimum of a sampled cost curve, or -1 (see the header, step 2).
int ClearMinimum(const std::vector<double>& curve, double log_step,
                 const FocalEstimationOptions& options) {
  const int n = static_cast<int>(curve.size());
  const int best = static_cast<int>(std::min_element(curve.begin(), curve.end()) - curve.begin());
  if (best == 0 || best == n - 1) return -1;
  const double best_cost = curve[best];
  if (best_cost > options.max_pair_cost) return -1;
  const double left_max = *std::max_element(curve.begin(), curve.begin() + best);
  const double right_max = *std::max_element(curve.begin() + best + 1, curve.end());
  const double rise = std::min(left_max, right_max) - best_cost;
  if (rise < options.min_cost_rise || rise < options.min_cost_rise_ratio * best_cost) return -1;
  for (int k = 0; k < n; ++k) {
    const bool local_minimum =
        (k == 0 || curve[k] <= curve[k - 1]) && (k == n - 1 || curve[k] <= curve[k + 1]);
    if (local_minimum && std::abs(k - best) * log_step > options.ambiguity_log_distance &&
        curve[k] < best_cost + 0.5 * rise) {
      return -1;
    }
  }
  return best;
}

// The value at which the cumulative weight of sorted (value, weight) pairs reaches half.
double WeightedMedian(std::vector<std::pair<double, double>> values) {
  std::sort(values.begin(), values.end());
  double total = 0.0;
  for (const auto& [value, weight] : values) total += weight;
  double cumulative = 0.0;
  for (const auto& [value, weight] : values) {
    cumulative += weight;
    if (cumulative >= 0.5 * total) return value;
  }
  return values.back().first;
}

// Weighted mean of the middle half of (value, weight) pairs: each value counts with the part
// of its weight that lies between the 25 % and 75 % points of the cumulative weight.
double InterquartileMean(std::vector<std::pair<double, double>> values) {
  std::sort(values.begin(), values.end());
  double total = 0.0;
  for (const auto& [value, weight] : values) total += weight;
  const double lo = 0.25 * total, hi = 0.75 * total;
  double before = 0.0, sum = 0.0, sum_weights = 0.0;
  for (const auto& [value, weight] : values) {
    const double part = std::max(0.0, std::min(before + weight, hi) - std::max(before, lo));
    sum += part * value;
    sum_weights += part;
    before += weight;
  }
  return sum / sum_weights;
}

}  // namespace

void FocalEstimationOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_focal_factor > 0 && std::isfinite(min_focal_factor),
                         "focal estimation: min_focal_factor must be positive, got {}",
                         min_focal_factor);
  LOOPSFM_REQUIRE_OPTION(max_focal_factor > min_focal_factor && std::isfinite(max_focal_factor),
                         "focal estimation: max_focal_factor must be finite and above "
                         "min_focal_factor ({}), got {}",
                         min_focal_factor, max_focal_factor);
  LOOPSFM_REQUIRE_OPTION(num_grid_samples >= 8 && num_grid_samples <= 100000,
                         "focal estimation: num_grid_samples must be in [8, 100000], got {}",
                         num_grid_samples);
  LOOPSFM_REQUIRE_OPTION(max_pair_cost > 0 && max_pair_cost < 1,
                         "focal estimation: max_pair_cost must be in (0, 1), got {}",
                         max_pair_cost);
  LOOPSFM_REQUIRE_OPTION(min_cost_rise >= 0 && min_cost_rise < 1,
                         "focal estimation: min_cost_rise must be in [0, 1), got {}",
                         min_cost_rise);
  LOOPSFM_REQUIRE_OPTION(min_cost_rise_ratio >= 0 && std::isfinite(min_cost_rise_ratio),
                         "focal estimation: min_cost_rise_ratio must be >= 0, got {}",
                         min_cost_rise_ratio);
  LOOPSFM_REQUIRE_OPTION(ambiguity_log_distance > 0 && std::isfinite(ambiguity_log_distance),
                         "focal estimation: ambiguity_log_distance must be positive, got {}",
                         ambiguity_log_distance);
  LOOPSFM_REQUIRE_OPTION(inlier_log_tolerance > 0 && std::isfinite(inlier_log_tolerance),
                         "focal estimation: inlier_log_tolerance must be positive, got {}",
                         inlier_log_tolerance);
  LOOPSFM_REQUIRE_OPTION(min_num_pairs >= 1, "focal estimation: min_num_pairs must be >= 1, got {}",
                         min_num_pairs);
  LOOPSFM_REQUIRE_OPTION(min_inlier_ratio >= 0 && min_inlier_ratio <= 1,
                         "focal estimation: min_inlier_ratio must be in [0, 1], got {}",
                         min_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(max_spread > 0 && std::isfinite(max_spread),
                         "focal estimation: max_spread must be positive, got {}", max_spread);
  LOOPSFM_REQUIRE_OPTION(refine_tolerance > 0 && refine_tolerance < 0.01,
                         "focal estimation: refine_tolerance must be in (0, 0.01), got {}",
                         refine_tolerance);
}

double EssentialSingularValueCost(const Eigen::Matrix3d& fundamental_matrix,
                                  const Eigen::Vector2d& principal_point, double focal_px) {
  Eigen::Matrix3d normalised;
  if (!(focal_px > 0.0) ||
      !NormaliseFundamental(fundamental_matrix, principal_point, focal_px, &normalised)) {
    return 1.0;
  }
  return NormalisedCost(normalised, 1.0);
}

FocalEstimate EstimateSharedFocalLength(std::span<const Eigen::Matrix3d> fundamental_matrices,
                                        std::span<const double> weights,
                                        const Eigen::Vector2d& principal_point, int width,
                                        int height, const FocalEstimationOptions& options) {
  options.Check();
  const int num_pairs = static_cast<int>(fundamental_matrices.size());
  LOOPSFM_REQUIRE_OPTION(weights.empty() || weights.size() == fundamental_matrices.size(),
                         "focal estimation: {} weights for {} fundamental matrices (give one "
                         "per pair, or none)",
                         weights.size(), fundamental_matrices.size());
  for (const double w : weights) {
    LOOPSFM_REQUIRE_OPTION(w >= 0 && std::isfinite(w),
                           "focal estimation: pair weights must be finite and >= 0, got {}", w);
  }
  LOOPSFM_REQUIRE_OPTION(width > 0 && height > 0,
                         "focal estimation: image size must be positive, got {} x {}", width,
                         height);
  LOOPSFM_REQUIRE_OPTION(principal_point.allFinite(),
                         "focal estimation: the principal point must be finite");

  FocalEstimate result;
  result.num_pairs = num_pairs;
  result.pair_focal_px.assign(num_pairs, 0.0);
  result.pair_is_inlier.assign(num_pairs, 0);
  auto weight = [&](int i) { return weights.empty() ? 1.0 : weights[i]; };

  // 1. Cost curves on the log grid of g = f / scale.
  const double scale = std::max(width, height);
  const int n = options.num_grid_samples;
  const double log_lo = std::log(options.min_focal_factor);
  const double log_hi = std::log(options.max_focal_factor);
  const double log_step = (log_hi - log_lo) / (n - 1);
  auto log_g_at = [&](int k) { return log_lo + k * log_step; };

  // 2. Pairs with a clear minimum, and their own estimates (log g).
  std::vector<Eigen::Matrix3d> normalised;
  std::vector<int> used;  // pair indices
  std::vector<double> used_log_g;
  std::vector<double> curve(n);
  for (int i = 0; i < num_pairs; ++i) {
    Eigen::Matrix3d g;
    if (!(weight(i) > 0.0) ||
        !NormaliseFundamental(fundamental_matrices[i], principal_point, scale, &g)) {
      continue;
    }
    for (int k = 0; k < n; ++k) curve[k] = NormalisedCost(g, std::exp(log_g_at(k)));
    const int best = ClearMinimum(curve, log_step, options);
    if (best < 0) continue;
    const double log_g =
        GoldenSectionMinimum([&](double x) { return NormalisedCost(g, std::exp(x)); },
                             log_g_at(best - 1), log_g_at(best + 1), options.refine_tolerance);
    result.pair_focal_px[i] = scale * std::exp(log_g);
    normalised.push_back(g);
    used.push_back(i);
    used_log_g.push_back(log_g);
  }
  result.num_pairs_used = static_cast<int>(used.size());
  if (result.num_pairs_used < options.min_num_pairs) {
    result.explanation = fmt::format(
        "only {} of {} pairs have a clear minimum of the essential-matrix cost over focal "
        "lengths of {}..{} x {} px (needs {}): views that do not turn (pure translation) or "
        "turn only about the optical axis, orbits that keep one point centred, and wrong "
        "fundamental matrices do not constrain the focal length",
        result.num_pairs_used, num_pairs, options.min_focal_factor, options.max_focal_factor, scale,
        options.min_num_pairs);
    return result;
  }

  // 3. Weighted vote over the pairs' own estimates: the grid sample with the most weight
  //    within inlier_log_tolerance (Epanechnikov kernel), then mean shift to the local mean.
  const double h = options.inlier_log_tolerance;
  int best_k = 0;
  double best_score = -1.0;
  for (int k = 0; k < n; ++k) {
    double score = 0.0;
    for (size_t j = 0; j < used.size(); ++j) {
      const double u = (used_log_g[j] - log_g_at(k)) / h;
      if (std::abs(u) < 1.0) score += weight(used[j]) * (1.0 - u * u);
    }
    if (score > best_score) {
      best_score = score;
      best_k = k;
    }
  }
  auto select_inliers = [&](double x) {
    std::vector<size_t> inliers;
    for (size_t j = 0; j < used.size(); ++j) {
      if (std::abs(used_log_g[j] - x) <= h &&
          NormalisedCost(normalised[j], std::exp(x)) <= options.max_pair_cost) {
        inliers.push_back(j);
      }
    }
    return inliers;
  };
  double log_g = log_g_at(best_k);
  for (int iteration = 0; iteration < 20; ++iteration) {
    double sum = 0.0, total_weight = 0.0;
    for (size_t j = 0; j < used.size(); ++j) {
      if (std::abs(used_log_g[j] - log_g) <= h) {
        sum += weight(used[j]) * used_log_g[j];
        total_weight += weight(used[j]);
      }
    }
    if (!(total_weight > 0.0) || std::abs(sum / total_weight - log_g) < 1e-9) break;
    log_g = sum / total_weight;
  }

  // 4. Inliers around the vote; f is the weighted interquartile mean of their own estimates.
  std::vector<size_t> inliers = select_inliers(log_g);
  if (!inliers.empty()) {
    std::vector<std::pair<double, double>> estimates;  // (log g, weight)
    for (const size_t j : inliers) estimates.emplace_back(used_log_g[j], weight(used[j]));
    log_g = InterquartileMean(std::move(estimates));
    inliers = select_inliers(log_g);
  }
  // 5. Spread of all used pairs' estimates around f.
  result.focal_px = scale * std::exp(log_g);
  result.num_pairs_inlier = static_cast<int>(inliers.size());
  for (const size_t j : inliers) result.pair_is_inlier[used[j]] = 1;
  std::vector<std::pair<double, double>> deviations;  // (|log(g_pair / g)|, weight)
  for (size_t j = 0; j < used.size(); ++j) {
    deviations.emplace_back(std::abs(used_log_g[j] - log_g), weight(used[j]));
  }
  result.spread = 1.4826 * WeightedMedian(std::move(deviations));

  // 6. Is it trustworthy?
  if (log_g <= log_lo + log_step || log_g >= log_hi - log_step) {
    result.explanation = fmt::format(
        "the best focal length lies at the end of the search range ({:.0f} px); widen "
        "min_focal_factor / max_focal_factor or check the pairs",
        result.focal_px);
  } else if (result.num_pairs_inlier < options.min_num_pairs ||
             result.num_pairs_inlier < options.min_inlier_ratio * result.num_pairs_used) {
    result.explanation = fmt::format(
        "only {} of the {} usable pairs agree on a focal length of {:.0f} px (needs {} and "
        "{:.0f} %): the pairs do not share one camera, or their fundamental matrices are wrong",
        result.num_pairs_inlier, result.num_pairs_used, result.focal_px, options.min_num_pairs,
        100.0 * options.min_inlier_ratio);
  } else if (result.spread > options.max_spread) {
    result.explanation = fmt::format(
        "the pairs' focal lengths scatter by {:.1f} % around {:.0f} px (at most {:.1f} % "
        "allowed)",
        100.0 * result.spread, result.focal_px, 100.0 * options.max_spread);
  } else {
    result.success = true;
  }
  return result;
}

}  // namespace loopsfm
