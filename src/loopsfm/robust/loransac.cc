#include "loopsfm/robust/loransac.h"

#include "loopsfm/util/errors.h"

namespace loopsfm {

void RansacOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(max_error > 0 && std::isfinite(max_error),
                         "RANSAC: max_error must be positive and finite, got {}", max_error);
  LOOPSFM_REQUIRE_OPTION(confidence > 0 && confidence < 1,
                         "RANSAC: confidence must be in (0, 1), got {}", confidence);
  LOOPSFM_REQUIRE_OPTION(num_trials_multiplier >= 1,
                         "RANSAC: num_trials_multiplier must be >= 1, got {}",
                         num_trials_multiplier);
  LOOPSFM_REQUIRE_OPTION(min_num_trials >= 0, "RANSAC: min_num_trials must be >= 0, got {}",
                         min_num_trials);
  LOOPSFM_REQUIRE_OPTION(max_num_trials >= 1 && max_num_trials >= min_num_trials,
                         "RANSAC: max_num_trials must be >= max(1, min_num_trials = {}), got {}",
                         min_num_trials, max_num_trials);
  LOOPSFM_REQUIRE_OPTION(max_local_optimization_iterations >= 0,
                         "RANSAC: max_local_optimization_iterations must be >= 0, got {}",
                         max_local_optimization_iterations);
}

int RansacNumTrials(double inlier_ratio, int sample_size, double confidence, double multiplier,
                    int max_num_trials) {
  // Probability that a sample is all inliers.
  const double p_good = std::pow(std::clamp(inlier_ratio, 0.0, 1.0), sample_size);
  if (p_good >= 1.0) return std::min(1, max_num_trials);
  if (p_good <= 0.0) return max_num_trials;
  // log1p keeps precision when p_good is tiny.
  const double num = multiplier * std::log(1.0 - confidence) / std::log1p(-p_good);
  if (!(num < static_cast<double>(max_num_trials))) return max_num_trials;
  return std::max(1, static_cast<int>(std::ceil(num)));
}

}  // namespace loopsfm
