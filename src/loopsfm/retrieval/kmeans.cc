#include "loopsfm/retrieval/kmeans.h"

#include <algorithm>
#include <atomic>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Rows per parallel task; results never depend on it.
constexpr int64_t kGrain = 512;

// Exact squared distance of two uint8 descriptors (at most 128 * 255^2 < 2^24).
inline int32_t SquaredDistance(const uint8_t* a, const uint8_t* b) {
  int32_t sum = 0;
  for (int i = 0; i < kDescriptorDim; ++i) {
    const int32_t d = static_cast<int32_t>(a[i]) - static_cast<int32_t>(b[i]);
    sum += d * d;
  }
  return sum;
}

// k-means++ seeding: the first centre uniformly, each next one with probability proportional
// to the squared distance to the nearest centre chosen so far. Integer arithmetic throughout,
// so the choice is exact. Stops early when every point coincides with a chosen centre.
std::vector<int64_t> SeedCentres(const uint8_t* rows, int64_t n, int k, Random& random) {
  std::vector<int64_t> seeds = {random.UniformInt(0, n - 1)};
  std::vector<int32_t> nearest(n);
  auto update = [&](const uint8_t* centre, bool first) {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, n, kGrain), [&](const auto& range) {
      for (int64_t i = range.begin(); i < range.end(); ++i) {
        const int32_t d = SquaredDistance(rows + i * kDescriptorDim, centre);
        nearest[i] = first ? d : std::min(nearest[i], d);
      }
    });
  };
  update(rows + seeds[0] * kDescriptorDim, true);
  while (static_cast<int>(seeds.size()) < k) {
    int64_t total = 0;
    for (int64_t i = 0; i < n; ++i) total += nearest[i];
    if (total == 0) break;
    const int64_t target = random.UniformInt(0, total - 1);
    int64_t cumulative = 0, chosen = n - 1;
    for (int64_t i = 0; i < n; ++i) {
      cumulative += nearest[i];
      if (cumulative > target) {
        chosen = i;
        break;
      }
    }
    seeds.push_back(chosen);
    update(rows + chosen * kDescriptorDim, false);
  }
  return seeds;
}

// Assigns every row to its nearest centre; returns how many labels changed.
int64_t Assign(const uint8_t* rows, int64_t n, const DescriptorCentres& centres,
               std::vector<uint32_t>& labels) {
  const int k = static_cast<int>(centres.rows());
  std::vector<float> squared_norms(k);
  for (int j = 0; j < k; ++j) squared_norms[j] = internal::SquaredNorm128(centres.row(j).data());
  std::atomic<int64_t> changed = 0;
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, n, kGrain), [&](const auto& range) {
    alignas(64) float x[kDescriptorDim];
    int64_t local_changed = 0;
    for (int64_t i = range.begin(); i < range.end(); ++i) {
      internal::ToFloat(rows + i * kDescriptorDim, x);
      const uint32_t label = static_cast<uint32_t>(
          internal::NearestCentre(x, centres.data(), squared_norms.data(), k));
      local_changed += label != labels[i];
      labels[i] = label;
    }
    changed += local_changed;
  });
  return changed;
}

// Exact per-cluster sums (integers, so independent of the summation order) and counts.
struct ClusterSums {
  std::vector<int64_t> sums;
  std::vector<int64_t> counts;
  explicit ClusterSums(int k) : sums(static_cast<size_t>(k) * kDescriptorDim, 0), counts(k, 0) {}
};

ClusterSums SumClusters(const uint8_t* rows, int64_t n, int k,
                        const std::vector<uint32_t>& labels) {
  tbb::combinable<ClusterSums> partial([k] { return ClusterSums(k); });
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, n, 4 * kGrain), [&](const auto& range) {
    ClusterSums& local = partial.local();
    for (int64_t i = range.begin(); i < range.end(); ++i) {
      const uint8_t* row = rows + i * kDescriptorDim;
      int64_t* sum = local.sums.data() + static_cast<size_t>(labels[i]) * kDescriptorDim;
      for (int d = 0; d < kDescriptorDim; ++d) sum[d] += row[d];
      ++local.counts[labels[i]];
    }
  });
  ClusterSums total(k);
  partial.combine_each([&](const ClusterSums& local) {
    for (size_t i = 0; i < total.sums.size(); ++i) total.sums[i] += local.sums[i];
    for (int j = 0; j < k; ++j) total.counts[j] += local.counts[j];
  });
  return total;
}

}  // namespace

void KMeansOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(num_clusters >= 1, "k-means needs at least one cluster, got {}",
                         num_clusters);
  LOOPSFM_REQUIRE_OPTION(max_iterations >= 0 && max_iterations <= 10000,
                         "k-means iterations must be between 0 and 10000, got {}", max_iterations);
}

KMeansResult KMeans(const uint8_t* rows, int64_t num_rows, const KMeansOptions& options,
                    Random& random) {
  options.Check();
  LOOPSFM_CHECK_GE(num_rows, 1);
  const int64_t n = num_rows;
  const std::vector<int64_t> seeds = SeedCentres(rows, n, options.num_clusters, random);
  int k = static_cast<int>(seeds.size());

  KMeansResult result;
  result.centres.resize(k, kDescriptorDim);
  for (int j = 0; j < k; ++j) {
    for (int d = 0; d < kDescriptorDim; ++d) {
      result.centres(j, d) = rows[seeds[j] * kDescriptorDim + d];
    }
  }
  result.labels.assign(n, std::numeric_limits<uint32_t>::max());
  Assign(rows, n, result.centres, result.labels);
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const ClusterSums sums = SumClusters(rows, n, k, result.labels);
    for (int j = 0; j < k; ++j) {
      if (sums.counts[j] == 0) continue;  // keeps its centre; may win points back
      const double inv = 1.0 / static_cast<double>(sums.counts[j]);
      for (int d = 0; d < kDescriptorDim; ++d) {
        result.centres(j, d) = static_cast<float>(
            static_cast<double>(sums.sums[static_cast<size_t>(j) * kDescriptorDim + d]) * inv);
      }
    }
    result.num_iterations = iteration + 1;
    if (Assign(rows, n, result.centres, result.labels) == 0) break;
  }

  // Drop clusters that ended empty, keeping the order of the others.
  std::vector<int64_t> sizes(k, 0);
  for (const uint32_t label : result.labels) ++sizes[label];
  std::vector<uint32_t> new_index(k);
  int kept = 0;
  for (int j = 0; j < k; ++j) {
    new_index[j] = kept;
    if (sizes[j] == 0) continue;
    if (kept != j) result.centres.row(kept) = result.centres.row(j);
    sizes[kept] = sizes[j];
    ++kept;
  }
  if (kept != k) {
    result.centres.conservativeResize(kept, Eigen::NoChange);
    for (uint32_t& label : result.labels) label = new_index[label];
  }
  sizes.resize(kept);
  result.sizes = std::move(sizes);
  return result;
}

}  // namespace loopsfm
