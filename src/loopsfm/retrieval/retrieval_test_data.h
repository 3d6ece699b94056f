#pragma once
// Synthetic SIFT-like descriptors for the retrieval tests: well-separated Gaussian clusters in
// the uint8 cube. Cluster centres are uniform in [40, 215]^128 (squared distance between two
// centres about 128 * 175^2 / 6 = 650k); points are centre + N(0, sigma^2) per coordinate,
// rounded and clamped (squared distance to their centre about 128 sigma^2).

#include <algorithm>
#include <cmath>
#include <vector>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/features.h"

namespace loopsfm::retrieval_test {

inline FeatureDescriptors RandomCentres(int num_clusters, Random& random) {
  FeatureDescriptors centres(num_clusters, kDescriptorDim);
  for (int i = 0; i < num_clusters; ++i) {
    for (int d = 0; d < kDescriptorDim; ++d) {
      centres(i, d) = static_cast<uint8_t>(random.UniformInt(40, 215));
    }
  }
  return centres;
}

// Appends `count` noisy copies of centre row `cluster` to `out` (resized as needed).
inline void DrawFromCluster(const FeatureDescriptors& centres, int cluster, int count, double sigma,
                            Random& random, FeatureDescriptors& out) {
  const int64_t first = out.rows();
  out.conservativeResize(first + count, Eigen::NoChange);
  for (int i = 0; i < count; ++i) {
    for (int d = 0; d < kDescriptorDim; ++d) {
      const double v = centres(cluster, d) + random.Normal(0.0, sigma);
      out(first + i, d) = static_cast<uint8_t>(std::clamp(std::round(v), 0.0, 255.0));
    }
  }
}

struct ClusteredDescriptors {
  FeatureDescriptors centres;
  FeatureDescriptors points;
  std::vector<int> cluster_of_point;
};

inline ClusteredDescriptors MakeClusters(int num_clusters, int points_per_cluster, double sigma,
                                         Random& random) {
  ClusteredDescriptors data;
  data.centres = RandomCentres(num_clusters, random);
  data.points.resize(0, kDescriptorDim);
  for (int c = 0; c < num_clusters; ++c) {
    DrawFromCluster(data.centres, c, points_per_cluster, sigma, random, data.points);
    data.cluster_of_point.insert(data.cluster_of_point.end(), points_per_cluster, c);
  }
  return data;
}

}  // namespace loopsfm::retrieval_test
