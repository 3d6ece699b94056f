#include "loopsfm/matching/view_graph_cleaning.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <tuple>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/random_rotations.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using testing::Noise;
using testing::OutlierRotation;
using testing::RandomRotation;

// True rotations of the nodes and noisy measurements of them.
struct TestGraph {
  std::map<image_t, Eigen::Quaterniond> truth;
  std::vector<RelativeRotation> edges;

  // The true cam2_from_cam1 of an edge.
  Eigen::Quaterniond TrueRotation(const RelativeRotation& edge) const {
    return truth.at(edge.node2) * truth.at(edge.node1).conjugate();
  }
  // Replaces the edge's measurement by an outlier.
  void MakeOutlier(int e, Random& random) {
    edges[e].cam2_from_cam1 = OutlierRotation(TrueRotation(edges[e]), random);
  }
  void AddNodes(image_t first, int n, Random& random) {
    for (int i = 0; i < n; ++i) truth[first + i] = RandomRotation(random);
  }
  // Measures the pair (in a random direction) unless it is already an edge.
  void AddEdge(image_t a, image_t b, double noise_deg, Random& random) {
    if (a == b || !pairs_.insert({std::min(a, b), std::max(a, b)}).second) return;
    if (random.UniformReal() < 0.5) std::swap(a, b);
    const Eigen::Quaterniond measured =
        Noise(random, noise_deg) * truth.at(b) * truth.at(a).conjugate();
    edges.push_back({.node1 = a, .node2 = b, .cam2_from_cam1 = measured, .weight = 100.0});
  }
  // Nodes first..first+n-1 and every pair of them.
  void AddClique(image_t first, int n, double noise_deg, Random& random) {
    AddNodes(first, n, random);
    for (image_t a = first; a < first + n; ++a) {
      for (image_t b = a + 1; b < first + n; ++b) AddEdge(a, b, noise_deg, random);
    }
  }
  // A video over first..first+n-1: each frame with its next `reach` frames, and
  // `num_revisits` returns to an earlier place, each a 3 x 3 block of pairs.
  void AddVideo(image_t first, int n, int reach, int num_revisits, double noise_deg,
                Random& random) {
    AddNodes(first, n, random);
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n && j <= i + reach; ++j)
        AddEdge(first + i, first + j, noise_deg, random);
    }
    for (int r = 0; r < num_revisits; ++r) {
      const int i = static_cast<int>(random.UniformInt(0, n - 3));
      const int j = static_cast<int>(random.UniformInt(0, n - 3));
      if (std::abs(i - j) <= reach + 3) continue;
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) AddEdge(first + i + a, first + j + b, noise_deg, random);
      }
    }
  }

 private:
  std::set<std::pair<image_t, image_t>> pairs_;
};

std::set<int> Kept(const ViewGraphCleaningResult& result) {
  return {result.kept_edges.begin(), result.kept_edges.end()};
}

TEST(ViewGraphCleaning, PlantedOutliersAreRemoved) {
  Random random(21);
  TestGraph graph;
  graph.AddVideo(0, 150, 4, 40, 1.0, random);
  const size_t num_edges = graph.edges.size();
  const auto outliers =
      random.Sample(static_cast<uint32_t>(num_edges), static_cast<uint32_t>(0.15 * num_edges));
  for (uint32_t e : outliers) graph.MakeOutlier(e, random);
  const ViewGraphCleaningResult result = CleanViewGraph(graph.edges);
  const std::set<int> kept = Kept(result);
  for (uint32_t e : outliers) EXPECT_FALSE(kept.count(static_cast<int>(e))) << "outlier " << e;
  const std::set<uint32_t> outlier_set(outliers.begin(), outliers.end());
  int good_dropped = 0;
  for (size_t e = 0; e < num_edges; ++e) {
    if (!outlier_set.count(static_cast<uint32_t>(e)) && !kept.count(static_cast<int>(e)))
      ++good_dropped;
  }
  const size_t num_good = num_edges - outliers.size();
  EXPECT_LE(good_dropped, static_cast<int>(0.03 * num_good));
  const ViewGraphCleaningReport& report = result.report;
  EXPECT_EQ(report.num_input_edges, static_cast<int>(num_edges));
  EXPECT_EQ(report.num_ignored_edges, 0);
  EXPECT_GT(report.num_triangles, static_cast<int>(num_edges));
  EXPECT_GT(report.num_failed_triangles, 0);
  EXPECT_EQ(report.num_edges, static_cast<int>(kept.size()));
  EXPECT_EQ(
      report.num_dropped_by_triangles + report.num_dropped_outside_component + report.num_edges,
      static_cast<int>(num_edges));
  EXPECT_EQ(report.num_nodes, 150);
  // Without outliers, 1 degree of noise drops next to nothing.
  TestGraph clean;
  Random clean_random(22);
  clean.AddVideo(0, 150, 4, 40, 1.0, clean_random);
  EXPECT_LE(CleanViewGraph(clean.edges).report.num_dropped_by_triangles,
            static_cast<int>(0.01 * clean.edges.size()));
}

TEST(ViewGraphCleaning, GoodEdgesSharingTrianglesWithOutliersStay) {
  // Five nodes, all ten pairs, two disjoint outliers (0, 1) and (2, 3): the good edge (0, 2)
  // passes only one of its three triangles until the outliers are gone.
  Random random(23);
  TestGraph graph;
  graph.AddClique(0, 5, 0.2, random);
  std::set<int> outliers;
  for (size_t e = 0; e < graph.edges.size(); ++e) {
    RelativeRotation& edge = graph.edges[e];
    const image_t low = std::min(edge.node1, edge.node2);
    const image_t high = std::max(edge.node1, edge.node2);
    if ((low == 0 && high == 1) || (low == 2 && high == 3)) {
      edge.cam2_from_cam1 = Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitX()) * edge.cam2_from_cam1;
      outliers.insert(static_cast<int>(e));
    }
  }
  ASSERT_EQ(outliers.size(), 2u);
  const ViewGraphCleaningResult result = CleanViewGraph(graph.edges);
  EXPECT_EQ(result.report.num_triangles, 10);
  EXPECT_EQ(result.report.num_dropped_by_triangles, 2);
  for (size_t e = 0; e < graph.edges.size(); ++e) {
    EXPECT_EQ(Kept(result).count(static_cast<int>(e)) == 0,
              outliers.count(static_cast<int>(e)) == 1)
        << "edge " << e;
  }
}

TEST(ViewGraphCleaning, OutliersThatPassATriangleTogetherAreDropped) {
  // Six nodes, all fifteen pairs. The outliers (0, 1) and (1, 2) carry errors that cancel
  // around the triangle (0, 1, 2), so each passes one triangle and fails the other three:
  // step 1 keeps them, step 2 drops them; the good edges at node 1 still pass half of theirs.
  Random random(27);
  TestGraph graph;
  graph.AddClique(0, 6, 0.2, random);
  const Eigen::Quaterniond error(Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, 2, 3).normalized()));
  std::set<int> outliers;
  for (size_t e = 0; e < graph.edges.size(); ++e) {
    RelativeRotation& edge = graph.edges[e];
    // cam1_from_cam0 becomes E R_10 and cam2_from_cam1 becomes R_21 E^-1, in either direction.
    const Eigen::Quaterniond truth = graph.TrueRotation(edge);
    if (std::min(edge.node1, edge.node2) == 0 && std::max(edge.node1, edge.node2) == 1) {
      edge.cam2_from_cam1 = edge.node1 == 0 ? error * truth : truth * error.conjugate();
    } else if (std::min(edge.node1, edge.node2) == 1 && std::max(edge.node1, edge.node2) == 2) {
      edge.cam2_from_cam1 = edge.node1 == 1 ? truth * error.conjugate() : error * truth;
    } else {
      continue;
    }
    outliers.insert(static_cast<int>(e));
  }
  ASSERT_EQ(outliers.size(), 2u);
  // With min_pass_fraction 0.6 the good edges (1, 3), (1, 4), (1, 5) start below it too (two
  // of four pass); dropping the worst first, the outliers, lifts them to all of their rest.
  ViewGraphCleaningOptions strict;
  strict.min_pass_fraction = 0.6;
  for (const ViewGraphCleaningOptions& options : {ViewGraphCleaningOptions(), strict}) {
    const ViewGraphCleaningResult result = CleanViewGraph(graph.edges, options);
    EXPECT_EQ(result.report.num_triangles, 20);
    EXPECT_EQ(result.report.num_failed_triangles, 6);
    EXPECT_EQ(result.report.num_dropped_by_triangles, 2);
    for (size_t e = 0; e < graph.edges.size(); ++e) {
      EXPECT_EQ(Kept(result).count(static_cast<int>(e)) == 0,
                outliers.count(static_cast<int>(e)) == 1)
          << "edge " << e << ", min_pass_fraction " << options.min_pass_fraction;
    }
  }
}

TEST(ViewGraphCleaning, WeighedTrianglesKeepAHeavyEdgeThatWeakOutliersOutnumber) {
  // As at a corner of block.mp4: frames 0-5 see one facade (pairs of 300 inliers); frame 6 is
  // tied to 5 and 7 by good pairs (200 and 60 inliers), and to 0-4 by weak pairs (25 inliers)
  // whose rotations are off, those from 0 and 1 by the same 13 degrees. Counted, the good
  // (5, 6) fails the triangles it shares with the two outliers that agree and is dropped, and
  // they stay; weighed by inliers, the outliers go and (5, 6) stays.
  Random random(31);
  TestGraph graph;
  graph.AddClique(0, 6, 0.2, random);
  graph.AddNodes(6, 2, random);
  for (RelativeRotation& edge : graph.edges) edge.weight = 300.0;
  const int good = static_cast<int>(graph.edges.size());
  for (const auto& [a, b, weight] : {std::tuple(5, 6, 200.0), {5, 7, 60.0}, {6, 7, 500.0}}) {
    graph.AddEdge(a, b, 0.2, random);
    graph.edges.back().weight = weight;
  }
  const std::vector<Eigen::AngleAxisd> errors = {
      {13.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()},
      {13.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()},
      {25.0 * M_PI / 180.0, Eigen::Vector3d::UnitX()},
      {35.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()},
      {45.0 * M_PI / 180.0, Eigen::Vector3d(1, 1, 0).normalized()}};
  std::set<int> outliers;
  for (image_t a = 0; a < 5; ++a) {
    outliers.insert(static_cast<int>(graph.edges.size()));
    const Eigen::Quaterniond truth = graph.truth.at(6) * graph.truth.at(a).conjugate();
    graph.edges.push_back({.node1 = a,
                           .node2 = 6,
                           .cam2_from_cam1 = Eigen::Quaterniond(errors[a]) * truth,
                           .weight = 25.0});
  }
  const ViewGraphCleaningResult counted = CleanViewGraph(graph.edges, ViewGraphCleaningOptions());
  EXPECT_EQ(Kept(counted).count(good), 0u);
  EXPECT_EQ(Kept(counted).count(*outliers.begin()), 1u);

  ViewGraphCleaningOptions weighed;
  weighed.weigh_triangles = true;
  const ViewGraphCleaningResult result = CleanViewGraph(graph.edges, weighed);
  EXPECT_EQ(result.report.num_dropped_by_triangles, 5);
  for (size_t e = 0; e < graph.edges.size(); ++e) {
    EXPECT_EQ(Kept(result).count(static_cast<int>(e)) == 0,
              outliers.count(static_cast<int>(e)) == 1)
        << "edge " << e;
  }
}

TEST(ViewGraphCleaning, OnlyTheLargestComponentIsKept) {
  Random random(24);
  TestGraph graph;
  graph.AddVideo(0, 40, 3, 3, 0.5, random);
  const size_t num_large = graph.edges.size();
  graph.AddVideo(100, 20, 3, 1, 0.5, random);
  const ViewGraphCleaningResult result = CleanViewGraph(graph.edges);
  EXPECT_EQ(result.report.num_nodes, 40);
  EXPECT_EQ(result.report.num_dropped_by_triangles, 0);
  EXPECT_EQ(result.report.num_dropped_outside_component,
            static_cast<int>(graph.edges.size() - num_large));
  ASSERT_EQ(result.kept_edges.size(), num_large);
  for (int e : result.kept_edges) EXPECT_LT(graph.edges[e].node1, 100u);
  ViewGraphCleaningOptions all;
  all.keep_largest_component = false;
  EXPECT_EQ(CleanViewGraph(graph.edges, all).kept_edges.size(), graph.edges.size());
}

TEST(ViewGraphCleaning, EdgesInNoTriangleAreKept) {
  Random random(25);
  TestGraph graph;
  graph.AddVideo(0, 20, 2, 0, 0.5, random);
  // A chain hanging off node 19, one of its edges a random rotation: nothing can tell.
  graph.AddNodes(20, 8, random);
  for (image_t i = 19; i < 27; ++i) graph.AddEdge(i, i + 1, 0.5, random);
  graph.edges.back().cam2_from_cam1 = RandomRotation(random);
  // A self-loop and a repeated pair (reversed) are ignored.
  graph.edges.push_back({.node1 = 4, .node2 = 4});
  RelativeRotation repeated = graph.edges.front();
  std::swap(repeated.node1, repeated.node2);
  graph.edges.push_back(repeated);
  const ViewGraphCleaningResult result = CleanViewGraph(graph.edges);
  EXPECT_EQ(result.report.num_ignored_edges, 2);
  EXPECT_EQ(result.report.num_edges_in_no_triangle, 8);
  EXPECT_EQ(result.report.num_dropped_by_triangles, 0);
  EXPECT_EQ(result.report.num_edges, static_cast<int>(graph.edges.size()) - 2);
  EXPECT_EQ(result.report.num_nodes, 28);
}

TEST(ViewGraphCleaning, LoopErrorIsTheAngleAroundTheTriangle) {
  Random random(26);
  const Eigen::Quaterniond r0 = RandomRotation(random), r1 = RandomRotation(random),
                           r2 = RandomRotation(random);
  const Eigen::Quaterniond error(Eigen::AngleAxisd(7.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  // Edges in mixed directions; one of them carries a 7 degree error.
  const RelativeRotation a{.node1 = 0, .node2 = 1, .cam2_from_cam1 = r1 * r0.conjugate()};
  const RelativeRotation b{.node1 = 2, .node2 = 1, .cam2_from_cam1 = error * r1 * r2.conjugate()};
  const RelativeRotation c{.node1 = 0, .node2 = 2, .cam2_from_cam1 = r2 * r0.conjugate()};
  EXPECT_NEAR(LoopErrorDegrees(a, b, c), 7.0, 1e-9);
  EXPECT_NEAR(LoopErrorDegrees(b, c, a), 7.0, 1e-9);
  EXPECT_NEAR(LoopErrorDegrees(c, a, b), 7.0, 1e-9);
  const RelativeRotation exact{.node1 = 2, .node2 = 1, .cam2_from_cam1 = r1 * r2.conjugate()};
  EXPECT_LT(LoopErrorDegrees(a, exact, c), 1e-9);
}

TEST(ViewGraphCleaning, BadOptionsThrow) {
  const auto throws = [](auto change) {
    ViewGraphCleaningOptions options;
    change(options);
    EXPECT_THROW(options.Check(), InvalidArgument);
    EXPECT_THROW(CleanViewGraph({}, options), InvalidArgument);
  };
  throws([](ViewGraphCleaningOptions& o) { o.max_loop_error_deg = 0.0; });
  throws([](ViewGraphCleaningOptions& o) { o.max_loop_error_deg = 180.0; });
  throws([](ViewGraphCleaningOptions& o) { o.max_loop_error_deg = std::nan(""); });
  throws([](ViewGraphCleaningOptions& o) { o.min_pass_fraction = 0.0; });
  throws([](ViewGraphCleaningOptions& o) { o.min_pass_fraction = 1.5; });
  EXPECT_NO_THROW(ViewGraphCleaningOptions().Check());
}

}  // namespace
}  // namespace loopsfm
