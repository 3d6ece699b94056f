#pragma once
// LO-RANSAC (Chum, Matas, Kittler 2003; Lebeda, Matas, Chum 2012): RANSAC with MSAC
// scoring in which every new best model is locally optimised by re-estimating it from its
// inliers with a non-minimal estimator until its score stops improving. The number of
// trials adapts to the best inlier ratio seen so far. All randomness comes from the
// Random passed in, so a run is reproducible for a given seed.
//
// An estimator holds its data (N items) and provides:
//   using Model = ...;
//   static constexpr int kMinNumSamples;                 // size of a minimal sample
//   size_t NumData() const;                               // N
//   std::vector<Model> Estimate(std::span<const uint32_t> sample) const;   // minimal solver
//   void Residuals(const Model&, std::vector<double>* squared_residuals) const;  // N values
// and optionally, for the local optimisation:
//   bool EstimateNonMinimal(std::span<const uint32_t> inliers, Model* model) const;
// which improves *model in place from the given inliers (e.g. by Gauss-Newton) and returns
// false when it cannot. Without it, LO-RANSAC is plain MSAC.

#include <algorithm>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "loopsfm/math/random.h"

namespace loopsfm {

template <typename E>
concept RansacEstimator = requires(const E& estimator, std::span<const uint32_t> sample,
                                   const typename E::Model& model, std::vector<double>* residuals) {
  { E::kMinNumSamples } -> std::convertible_to<int>;
  { estimator.NumData() } -> std::convertible_to<size_t>;
  { estimator.Estimate(sample) } -> std::same_as<std::vector<typename E::Model>>;
  estimator.Residuals(model, residuals);
};

template <typename E>
concept LocallyOptimizableEstimator =
    RansacEstimator<E> && requires(const E& estimator, std::span<const uint32_t> inliers,
                                   typename E::Model* model) {
      { estimator.EstimateNonMinimal(inliers, model) } -> std::convertible_to<bool>;
    };

struct RansacOptions {
  // Inlier threshold on the residual (not squared), in the estimator's residual units;
  // no default, it must be set.
  double max_error = 0.0;
  // Probability of having drawn at least one all-inlier sample when the run stops early.
  double confidence = 0.9999;
  // Factor on the number of trials given by the confidence, against noisy inlier samples.
  double num_trials_multiplier = 3.0;
  // Trials always made (unless every datum is an inlier of an earlier model).
  int min_num_trials = 0;
  // Trials never exceeded.
  int max_num_trials = 10000;
  // Re-estimate every new best model from its inliers (when the estimator supports it).
  bool local_optimization = true;
  // Rounds of re-estimation per local optimisation; each round must improve the score.
  int max_local_optimization_iterations = 10;
  void Check() const;
};

template <typename Model>
struct RansacReport {
  // True when a model with at least kMinNumSamples inliers was found.
  bool success = false;
  // Minimal samples drawn.
  int num_trials = 0;
  // Successful local optimisation rounds.
  int num_local_optimizations = 0;
  int num_inliers = 0;
  // One entry per datum: 1 for inliers of the returned model.
  std::vector<char> inlier_mask;
  Model model{};
};

// Number of trials needed to draw an all-inlier sample of size sample_size with
// probability `confidence` when a fraction inlier_ratio of the data are inliers, times
// the multiplier; saturates at max_num_trials.
int RansacNumTrials(double inlier_ratio, int sample_size, double confidence, double multiplier,
                    int max_num_trials);

namespace internal {

// k distinct indices from [0, n) by rejection (k is small); k <= n.
inline void DrawSample(Random& random, uint32_t n, int k, std::vector<uint32_t>* sample) {
  sample->clear();
  while (static_cast<int>(sample->size()) < k) {
    const auto index = static_cast<uint32_t>(random.UniformInt(0, n - 1));
    if (std::find(sample->begin(), sample->end(), index) == sample->end()) {
      sample->push_back(index);
    }
  }
}

// MSAC score (sum of truncated squared residuals, lower is better) and inlier count.
struct Support {
  int num_inliers = 0;
  double score = std::numeric_limits<double>::max();
};

inline Support EvaluateSupport(const std::vector<double>& squared_residuals,
                               double squared_max_error) {
  Support support;
  support.score = 0.0;
  for (const double r : squared_residuals) {
    if (r <= squared_max_error) {
      ++support.num_inliers;
      support.score += r;
    } else {
      support.score += squared_max_error;
    }
  }
  return support;
}

inline void InlierIndices(const std::vector<double>& squared_residuals, double squared_max_error,
                          std::vector<uint32_t>* inliers) {
  inliers->clear();
  for (size_t i = 0; i < squared_residuals.size(); ++i) {
    if (squared_residuals[i] <= squared_max_error) inliers->push_back(static_cast<uint32_t>(i));
  }
}

}  // namespace internal

template <RansacEstimator Estimator>
RansacReport<typename Estimator::Model> LoRansac(const Estimator& estimator,
                                                 const RansacOptions& options, Random& random) {
  using Model = typename Estimator::Model;
  options.Check();
  RansacReport<Model> report;
  const size_t num_data = estimator.NumData();
  constexpr int kSampleSize = Estimator::kMinNumSamples;
  if (num_data < static_cast<size_t>(kSampleSize)) return report;

  const double squared_max_error = options.max_error * options.max_error;
  std::vector<uint32_t> sample, inliers;
  std::vector<double> residuals;
  internal::Support best_support;
  Model best_model{};
  bool have_model = false;
  int max_num_trials = options.max_num_trials;

  // Re-estimates `model` from its inliers while the score improves.
  auto local_optimization = [&](Model* model, internal::Support* support) {
    if constexpr (LocallyOptimizableEstimator<Estimator>) {
      if (!options.local_optimization) return;
      for (int iter = 0; iter < options.max_local_optimization_iterations; ++iter) {
        estimator.Residuals(*model, &residuals);
        internal::InlierIndices(residuals, squared_max_error, &inliers);
        if (inliers.size() < static_cast<size_t>(kSampleSize)) return;
        Model refined = *model;
        if (!estimator.EstimateNonMinimal(inliers, &refined)) return;
        estimator.Residuals(refined, &residuals);
        const internal::Support refined_support =
            internal::EvaluateSupport(residuals, squared_max_error);
        if (!(refined_support.score < support->score)) return;
        *model = refined;
        *support = refined_support;
        ++report.num_local_optimizations;
      }
    }
  };

  for (report.num_trials = 0; report.num_trials < max_num_trials;) {
    ++report.num_trials;
    internal::DrawSample(random, static_cast<uint32_t>(num_data), kSampleSize, &sample);
    for (Model& model : estimator.Estimate(sample)) {
      estimator.Residuals(model, &residuals);
      internal::Support support = internal::EvaluateSupport(residuals, squared_max_error);
      if (!(support.score < best_support.score)) continue;
      local_optimization(&model, &support);
      best_model = model;
      best_support = support;
      have_model = true;
      max_num_trials = std::max(
          options.min_num_trials,
          RansacNumTrials(static_cast<double>(best_support.num_inliers) / num_data, kSampleSize,
                          options.confidence, options.num_trials_multiplier,
                          options.max_num_trials));
    }
    if (have_model && best_support.num_inliers == static_cast<int>(num_data)) break;
  }
  if (!have_model) return report;

  estimator.Residuals(best_model, &residuals);
  report.inlier_mask.assign(num_data, 0);
  for (size_t i = 0; i < num_data; ++i) {
    if (residuals[i] <= squared_max_error) {
      report.inlier_mask[i] = 1;
      ++report.num_inliers;
    }
  }
  report.model = best_model;
  report.success = report.num_inliers >= kSampleSize;
  return report;
}

}  // namespace loopsfm
