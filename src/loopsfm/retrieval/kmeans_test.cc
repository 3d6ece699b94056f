#include "loopsfm/retrieval/kmeans.h"

#include <set>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "loopsfm/retrieval/retrieval_test_data.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using retrieval_test::MakeClusters;

TEST(KMeans, FindsWellSeparatedClustersExactly) {
  Random random(7);
  const auto data = MakeClusters(8, 50, 3.0, random);
  KMeansOptions options;
  options.num_clusters = 8;
  const KMeansResult result = KMeans(data.points.data(), data.points.rows(), options, random);
  ASSERT_EQ(result.centres.rows(), 8);
  // A bijection between true clusters and labels.
  std::vector<int> label_of_cluster(8, -1);
  for (size_t i = 0; i < result.labels.size(); ++i) {
    const int c = data.cluster_of_point[i];
    if (label_of_cluster[c] < 0) label_of_cluster[c] = static_cast<int>(result.labels[i]);
    EXPECT_EQ(static_cast<int>(result.labels[i]), label_of_cluster[c]) << "point " << i;
  }
  EXPECT_EQ(std::set<int>(label_of_cluster.begin(), label_of_cluster.end()).size(), 8u);
  for (int c = 0; c < 8; ++c) {
    EXPECT_EQ(result.sizes[label_of_cluster[c]], 50);
    // The mean of 50 points with sigma 3 is within ~0.4 of the centre per coordinate.
    const Eigen::VectorXf error =
        result.centres.row(label_of_cluster[c]) - data.centres.row(c).cast<float>();
    EXPECT_LT(error.cwiseAbs().maxCoeff(), 2.0f) << "cluster " << c;
  }
  EXPECT_GE(result.num_iterations, 1);
}

TEST(KMeans, ReturnsFewerCentresForFewerDistinctPoints) {
  Random random(3);
  const auto data = MakeClusters(3, 1, 0.0, random);
  FeatureDescriptors points(30, kDescriptorDim);
  for (int i = 0; i < 30; ++i) points.row(i) = data.centres.row(i % 3);
  KMeansOptions options;
  options.num_clusters = 10;
  const KMeansResult result = KMeans(points.data(), points.rows(), options, random);
  ASSERT_EQ(result.centres.rows(), 3);
  EXPECT_EQ(result.sizes, std::vector<int64_t>({10, 10, 10}));
  for (int i = 0; i < 30; ++i) {
    EXPECT_EQ(result.centres.row(result.labels[i]), points.row(i).cast<float>());
  }
  const KMeansResult one = KMeans(points.data(), 1, options, random);
  EXPECT_EQ(one.centres.rows(), 1);
  EXPECT_EQ(one.labels, std::vector<uint32_t>({0}));
}

TEST(KMeans, SameResultForAnyThreadCount) {
  Random data_random(11);
  // Overlapping clusters, so that Lloyd runs several iterations.
  const auto data = MakeClusters(20, 200, 40.0, data_random);
  KMeansOptions options;
  options.num_clusters = 16;
  options.max_iterations = 5;
  KMeansResult parallel, serial;
  {
    Random random(5);
    parallel = KMeans(data.points.data(), data.points.rows(), options, random);
  }
  {
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    Random random(5);
    serial = KMeans(data.points.data(), data.points.rows(), options, random);
  }
  EXPECT_EQ(parallel.labels, serial.labels);
  ASSERT_EQ(parallel.centres.rows(), serial.centres.rows());
  EXPECT_TRUE((parallel.centres.array() == serial.centres.array()).all());
  EXPECT_GT(parallel.num_iterations, 1);
}

TEST(KMeans, RejectsBadOptions) {
  KMeansOptions options;
  options.num_clusters = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options.num_clusters = 4;
  options.max_iterations = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
