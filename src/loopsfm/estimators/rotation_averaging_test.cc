#include "loopsfm/estimators/rotation_averaging.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include <Eigen/SVD>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/random_rotations.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using testing::Noise;
using testing::OutlierRotation;
using testing::RandomRotation;

// A video's view graph over nodes first..first+n-1: every frame with the next `reach`
// frames, plus `num_loops` random pairs further apart (revisits).
std::vector<std::pair<image_t, image_t>> VideoGraph(image_t first, int n, int reach, int num_loops,
                                                    Random& random) {
  std::set<std::pair<image_t, image_t>> pairs;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n && j <= i + reach; ++j) pairs.insert({first + i, first + j});
  }
  int added = 0;
  while (added < num_loops) {
    const int i = static_cast<int>(random.UniformInt(0, n - 1));
    const int j = static_cast<int>(random.UniformInt(0, n - 1));
    if (std::abs(i - j) <= reach) continue;
    if (pairs.insert({first + std::min(i, j), first + std::max(i, j)}).second) ++added;
  }
  return {pairs.begin(), pairs.end()};
}

// Measurements of the true rotations with noise; the pair's order is flipped at random so
// both edge directions occur. Weights look like inlier counts.
std::vector<RelativeRotation> Measure(const std::map<image_t, Eigen::Quaterniond>& truth,
                                      const std::vector<std::pair<image_t, image_t>>& pairs,
                                      double noise_deg, Random& random) {
  std::vector<RelativeRotation> edges;
  for (auto [a, b] : pairs) {
    if (random.UniformReal() < 0.5) std::swap(a, b);
    RelativeRotation edge;
    edge.node1 = a;
    edge.node2 = b;
    edge.cam2_from_cam1 = Noise(random, noise_deg) * truth.at(b) * truth.at(a).conjugate();
    edge.weight = static_cast<double>(random.UniformInt(50, 500));
    edges.push_back(edge);
  }
  return edges;
}

// Replaces about `fraction` of the edges, in random order, by outlier rotations, skipping an
// edge where a node would be left with fewer than two more good edges than outliers (a node
// that outliers outnumber cannot be told from them). Returns the outliers' indices.
std::set<int> PlantOutliers(const std::map<image_t, Eigen::Quaterniond>& truth,
                            std::vector<RelativeRotation>* edges, double fraction, Random& random) {
  std::map<image_t, int> good, bad;
  for (const RelativeRotation& edge : *edges) {
    ++good[edge.node1];
    ++good[edge.node2];
  }
  std::set<int> outliers;
  const auto wanted = static_cast<size_t>(fraction * edges->size());
  for (uint32_t e :
       random.Sample(static_cast<uint32_t>(edges->size()), static_cast<uint32_t>(edges->size()))) {
    if (outliers.size() == wanted) break;
    RelativeRotation& edge = (*edges)[e];
    const auto keeps_majority = [&](image_t node) { return good[node] - 1 >= bad[node] + 1 + 2; };
    if (!keeps_majority(edge.node1) || !keeps_majority(edge.node2)) continue;
    for (image_t node : {edge.node1, edge.node2}) {
      --good[node];
      ++bad[node];
    }
    edge.cam2_from_cam1 =
        OutlierRotation(truth.at(edge.node2) * truth.at(edge.node1).conjugate(), random);
    outliers.insert(static_cast<int>(e));
  }
  return outliers;
}

std::map<image_t, Eigen::Quaterniond> RandomRotations(image_t first, int n, Random& random) {
  std::map<image_t, Eigen::Quaterniond> rotations;
  for (int i = 0; i < n; ++i) rotations[first + i] = RandomRotation(random);
  return rotations;
}

// Per node of `estimate`, the angle to the truth after the one world rotation that best
// aligns the two (chordal mean of the per-node alignments); degrees.
std::vector<double> AlignedErrorsDeg(const std::map<image_t, Eigen::Quaterniond>& estimate,
                                     const std::map<image_t, Eigen::Quaterniond>& truth) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (const auto& [id, rotation] : estimate) {
    sum += (truth.at(id).conjugate() * rotation).toRotationMatrix();
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant();
  const Eigen::Quaterniond world(svd.matrixU() * d * svd.matrixV().transpose());
  std::vector<double> errors;
  for (const auto& [id, rotation] : estimate) {
    errors.push_back((truth.at(id) * world).angularDistance(rotation) * 180.0 / M_PI);
  }
  return errors;
}

RotationAveragingOptions MaxWeightTree() {
  RotationAveragingOptions options;
  options.initialization = RotationInitialization::kMaxWeightTree;
  return options;
}

double Mean(const std::vector<double>& values) {
  double sum = 0.0;
  for (double v : values) sum += v;
  return values.empty() ? 0.0 : sum / values.size();
}

double Max(const std::vector<double>& values) {
  return values.empty() ? 0.0 : *std::max_element(values.begin(), values.end());
}

TEST(RotationAveraging, NoisyVideoGraphIsRecovered) {
  Random random(11);
  const auto truth = RandomRotations(0, 100, random);
  const auto edges = Measure(truth, VideoGraph(0, 100, 2, 100, random), 1.0, random);
  const RotationAveragingResult result = AverageRotations(edges);
  ASSERT_TRUE(result.report.success);
  EXPECT_TRUE(result.report.converged);
  EXPECT_EQ(result.report.num_nodes, 100);
  EXPECT_EQ(result.report.num_edges, static_cast<int>(edges.size()));
  ASSERT_EQ(result.cam_from_world.size(), 100u);
  const std::vector<double> errors = AlignedErrorsDeg(result.cam_from_world, truth);
  EXPECT_LT(Mean(errors), 0.8);
  EXPECT_LT(Max(errors), 2.5);
  // Averaging beats the spanning tree, which piles up the noise of its path.
  const std::vector<double> tree_errors =
      AlignedErrorsDeg(InitialRotations(edges, MaxWeightTree()), truth);
  EXPECT_GT(Mean(tree_errors), 1.5 * Mean(errors));
  // With 1 degree of noise no edge is left far from the estimate.
  EXPECT_EQ(result.report.num_outlier_edges, 0);
  EXPECT_LT(Max(result.report.edge_residual_deg), 5.0);
}

TEST(RotationAveraging, OutlierEdgesAreIgnored) {
  Random random(12);
  const auto truth = RandomRotations(0, 100, random);
  auto edges = Measure(truth, VideoGraph(0, 100, 4, 100, random), 1.0, random);
  // A fifth of the edges (any of them, tree edges included) become random rotations.
  const std::set<int> outliers = PlantOutliers(truth, &edges, 0.2, random);
  ASSERT_GE(outliers.size(), static_cast<size_t>(0.19 * edges.size()));
  const RotationAveragingResult result = AverageRotations(edges);
  ASSERT_TRUE(result.report.success);
  ASSERT_EQ(result.cam_from_world.size(), 100u);
  const std::vector<double> errors = AlignedErrorsDeg(result.cam_from_world, truth);
  EXPECT_LT(Mean(errors), 1.0);
  EXPECT_LT(Max(errors), 3.0);
  int good_above = 0;
  for (size_t e = 0; e < edges.size(); ++e) {
    const double residual = result.report.edge_residual_deg[e];
    if (outliers.count(static_cast<int>(e))) {
      EXPECT_GT(residual, 10.0) << "outlier edge " << e;
    } else if (residual > 5.0) {
      ++good_above;
    }
  }
  EXPECT_EQ(good_above, 0);
  EXPECT_EQ(result.report.num_outlier_edges, static_cast<int>(outliers.size()));
  // Plain least squares (no L1 stage, a huge robust scale) is pulled away by the outliers.
  RotationAveragingOptions plain;
  plain.num_l1_iterations = 0;
  plain.robust_scale_deg = 1e6;
  const RotationAveragingResult least_squares = AverageRotations(edges, plain);
  EXPECT_GT(Mean(AlignedErrorsDeg(least_squares.cam_from_world, truth)), 3.0 * Mean(errors));
}

TEST(RotationAveraging, SpanningTreeIsExactWithoutNoise) {
  Random random(13);
  const auto truth = RandomRotations(5, 100, random);
  auto edges = Measure(truth, VideoGraph(5, 100, 2, 60, random), 0.0, random);
  // Outlier edges lighter than every true one: the maximum-weight tree never takes them.
  for (int k = 0; k < 20; ++k) {
    edges[random.UniformInt(0, static_cast<int64_t>(edges.size()) - 1)].weight = 1.0;
  }
  for (RelativeRotation& edge : edges) {
    if (edge.weight == 1.0) edge.cam2_from_cam1 = RandomRotation(random);
  }
  const auto tree = InitialRotations(edges, MaxWeightTree());
  ASSERT_EQ(tree.size(), 100u);
  EXPECT_LT(Max(AlignedErrorsDeg(tree, truth)), 1e-6);
  // The root is the node with the largest total weight and keeps the identity.
  int identities = 0;
  for (const auto& [id, rotation] : tree) {
    if (rotation.angularDistance(Eigen::Quaterniond::Identity()) < 1e-12) ++identities;
  }
  EXPECT_EQ(identities, 1);
  // Noise-free and outlier-free data is a fixed point of the whole method.
  const auto clean = Measure(truth, VideoGraph(5, 100, 2, 60, random), 0.0, random);
  const RotationAveragingResult result = AverageRotations(clean);
  ASSERT_TRUE(result.report.success);
  EXPECT_TRUE(result.report.converged);
  EXPECT_LT(Max(AlignedErrorsDeg(result.cam_from_world, truth)), 1e-6);
  EXPECT_LT(Max(result.report.edge_residual_deg), 1e-6);
}

TEST(RotationAveraging, ConsensusTreeOutvotesAHeavyOutlier) {
  Random random(16);
  const auto truth = RandomRotations(0, 60, random);
  auto edges = Measure(truth, VideoGraph(0, 60, 2, 0, random), 0.0, random);
  // Node 10's edges are the heaviest, so it is the root; the edge (40, 41) is an outlier
  // heavier than the rest, so the maximum-weight tree takes it.
  int num_outliers = 0;
  for (RelativeRotation& edge : edges) {
    edge.weight = (edge.node1 == 10 || edge.node2 == 10) ? 200.0 : 100.0;
    if (std::min(edge.node1, edge.node2) == 40 && std::max(edge.node1, edge.node2) == 41) {
      edge.weight = 150.0;
      edge.cam2_from_cam1 =
          OutlierRotation(truth.at(edge.node2) * truth.at(edge.node1).conjugate(), random);
      ++num_outliers;
    }
  }
  ASSERT_EQ(num_outliers, 1);
  EXPECT_GT(Max(AlignedErrorsDeg(InitialRotations(edges, MaxWeightTree()), truth)), 10.0);
  const auto consensus = InitialRotations(edges);
  ASSERT_EQ(consensus.size(), 60u);
  EXPECT_LT(Max(AlignedErrorsDeg(consensus, truth)), 1e-6);
  EXPECT_LT(consensus.at(10).angularDistance(Eigen::Quaterniond::Identity()), 1e-12);
  // The L1 and robust stages repair the tree's start as well.
  for (const auto& options : {RotationAveragingOptions(), MaxWeightTree()}) {
    const RotationAveragingResult result = AverageRotations(edges, options);
    EXPECT_LT(Max(AlignedErrorsDeg(result.cam_from_world, truth)), 1e-3);
    EXPECT_EQ(result.report.num_outlier_edges, 1);
  }
}

TEST(RotationAveraging, OnlyTheLargestComponentIsReturned) {
  Random random(14);
  auto truth = RandomRotations(0, 30, random);
  const auto small = RandomRotations(100, 10, random);
  truth.insert(small.begin(), small.end());
  auto edges = Measure(truth, VideoGraph(0, 30, 2, 10, random), 0.5, random);
  const size_t num_large_edges = edges.size();
  const auto small_edges = Measure(truth, VideoGraph(100, 10, 2, 3, random), 0.5, random);
  edges.insert(edges.end(), small_edges.begin(), small_edges.end());
  edges.push_back({.node1 = 7, .node2 = 7});                     // a self-loop
  edges.push_back({.node1 = 200, .node2 = 201, .weight = 0.0});  // an unusable weight
  const RotationAveragingResult result = AverageRotations(edges);
  ASSERT_TRUE(result.report.success);
  EXPECT_EQ(result.report.num_ignored_edges, 2);
  EXPECT_EQ(result.report.num_nodes, 30);
  EXPECT_EQ(result.report.num_edges, static_cast<int>(num_large_edges));
  ASSERT_EQ(result.cam_from_world.size(), 30u);
  for (const auto& [id, rotation] : result.cam_from_world) EXPECT_LT(id, 30u);
  EXPECT_LT(Max(AlignedErrorsDeg(result.cam_from_world, truth)), 1.5);
  for (size_t e = 0; e < edges.size(); ++e) {
    if (e < num_large_edges) {
      EXPECT_GE(result.report.edge_residual_deg[e], 0.0);
    } else {
      EXPECT_EQ(result.report.edge_residual_deg[e], -1.0);
    }
  }
  EXPECT_EQ(InitialRotations(edges, MaxWeightTree()).size(), 30u);
}

TEST(RotationAveraging, NoUsableEdgeIsNoSuccess) {
  const RotationAveragingResult result = AverageRotations({{.node1 = 3, .node2 = 3}});
  EXPECT_FALSE(result.report.success);
  EXPECT_TRUE(result.cam_from_world.empty());
  EXPECT_EQ(result.report.num_ignored_edges, 1);
}

TEST(RotationAveraging, ResidualIsTheAngleBetweenMeasuredAndEstimated) {
  Random random(15);
  const Eigen::Quaterniond r1 = RandomRotation(random), r2 = RandomRotation(random);
  const Eigen::Quaterniond offset(Eigen::AngleAxisd(7.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()));
  const RelativeRotation edge{
      .node1 = 0, .node2 = 1, .cam2_from_cam1 = offset * r2 * r1.conjugate()};
  EXPECT_NEAR(RotationResidualDegrees(edge, r1, r2), 7.0, 1e-9);
}

TEST(RotationAveraging, BadOptionsThrow) {
  const auto throws = [](auto change) {
    RotationAveragingOptions options;
    change(options);
    EXPECT_THROW(options.Check(), InvalidArgument);
    EXPECT_THROW(AverageRotations({}, options), InvalidArgument);
  };
  throws([](RotationAveragingOptions& o) { o.num_l1_iterations = -1; });
  throws([](RotationAveragingOptions& o) { o.num_l1_inner_iterations = 0; });
  throws([](RotationAveragingOptions& o) { o.max_num_iterations = -1; });
  throws([](RotationAveragingOptions& o) { o.convergence_threshold_deg = 0.0; });
  throws([](RotationAveragingOptions& o) { o.robust_scale_deg = -2.0; });
  throws([](RotationAveragingOptions& o) { o.robust_scale_deg = std::nan(""); });
  throws([](RotationAveragingOptions& o) { o.outlier_threshold_deg = 0.0; });
  EXPECT_NO_THROW(RotationAveragingOptions().Check());
}

}  // namespace
}  // namespace loopsfm
