#pragma once
// Flat k-means on uint8 SIFT descriptors: the building block of the vocabulary tree.
//
// Seeding is k-means++ (Arthur & Vassilvitskii 2007) in exact integer arithmetic, then Lloyd
// iterations with float centres. Assignment runs in parallel (TBB) but every per-point result
// and every centre sum is computed exactly the same way whatever the thread count (centre sums
// are exact integer sums), so the result depends only on the input and the seed.

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/features.h"

namespace loopsfm {

// Float centres of descriptor clusters, one per row (same layout as FeatureDescriptors).
using DescriptorCentres = Eigen::Matrix<float, Eigen::Dynamic, kDescriptorDim, Eigen::RowMajor>;

struct KMeansOptions {
  // Number of clusters k (fewer are returned when the input has fewer distinct rows).
  int num_clusters = 10;
  // Maximum number of Lloyd updates; stops earlier once no point changes cluster.
  int max_iterations = 10;
  // Throws loopsfm::InvalidArgument with a readable message.
  void Check() const;
};

struct KMeansResult {
  // One row per non-empty cluster: every centre has at least one point assigned to it.
  DescriptorCentres centres;
  // Per input row, the index of its nearest centre (the assignment the centres were last
  // compared against; ties go to the lower index).
  std::vector<uint32_t> labels;
  // Number of points in each cluster.
  std::vector<int64_t> sizes;
  // Lloyd updates performed.
  int num_iterations = 0;
};

// Clusters `num_rows` descriptors stored contiguously row-major at `rows` (128 bytes each,
// e.g. FeatureDescriptors::data()). Requires num_rows >= 1.
KMeansResult KMeans(const uint8_t* rows, int64_t num_rows, const KMeansOptions& options,
                    Random& random);

namespace internal {

// Dot product of two 128-float vectors, with a fixed summation order.
inline float Dot128(const float* a, const float* b) {
  using Vec = Eigen::Matrix<float, kDescriptorDim, 1>;
  return Eigen::Map<const Vec>(a).dot(Eigen::Map<const Vec>(b));
}

inline float SquaredNorm128(const float* a) { return Dot128(a, a); }

// Index of the centre nearest to x among `num` consecutive centre rows, by |c|^2 - 2 x.c
// (|x|^2 is common to all; squared_norms from SquaredNorm128); ties go to the lower index.
// Shared by training and quantisation, so that both send a descriptor to the same centre.
// Fixed-size Eigen expressions: the summation order does not depend on memory alignment.
// Independent dot products beat a transposed layout of 16 centres per vector register
// (docs/benchmarks.md, "Vocabulary tree").
inline int NearestCentre(const float* x, const float* centres, const float* squared_norms,
                         int num) {
  int best = 0;
  float best_score = squared_norms[0] - 2.0f * Dot128(x, centres);
  for (int j = 1; j < num; ++j) {
    const float score = squared_norms[j] - 2.0f * Dot128(x, centres + j * kDescriptorDim);
    if (score < best_score) {
      best_score = score;
      best = j;
    }
  }
  return best;
}

inline void ToFloat(const uint8_t* descriptor, float* out) {
  for (int i = 0; i < kDescriptorDim; ++i) out[i] = static_cast<float>(descriptor[i]);
}

}  // namespace internal
}  // namespace loopsfm
