#include "loopsfm/matching/view_graph_bridging.h"

#include <gtest/gtest.h>

#include <functional>

#include "loopsfm/math/graph.h"
#include "loopsfm/matching/pairing_test_util.h"

namespace loopsfm {
namespace {

struct BridgeCase {
  int n;
  std::function<bool(int, int)> truth;  // i < j
  std::vector<image_t> ids;
  IndexPairSet tried, verified;
  size_t calls = 0;

  BridgeCase(int n_, std::function<bool(int, int)> t) : n(n_), truth(std::move(t)) {
    for (int i = 0; i < n; ++i) ids.push_back(i + 1);
    tried = verified = IndexPairSet(n);
    // Sequential pairs up to 3 apart were tried before.
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n && j <= i + 3; ++j) {
        tried.Insert(i, j);
        if (truth(i, j)) verified.Insert(i, j);
      }
    }
  }
  int NumComponents() const { return ConnectedComponents(n, verified.SortedPairs()).NumComponents(); }
  // `scores`: a dense test similarity (empty: none), given as each frame's best 32 candidates.
  ViewGraphBridgingReport Bridge(const Eigen::MatrixXf& scores,
                                 const ViewGraphBridgingOptions& options = {}) {
    auto verify = [&](const std::vector<ImagePair>& pairs) {
      std::vector<bool> ok;
      for (const ImagePair& p : pairs) {
        const int i = static_cast<int>(p.image_id1) - 1, j = static_cast<int>(p.image_id2) - 1;
        EXPECT_FALSE(tried.Contains(i, j)) << "tried twice: " << i << ", " << j;
        ok.push_back(truth(std::min(i, j), std::max(i, j)));
      }
      calls += pairs.size();
      return ok;
    };
    const std::vector<std::vector<ScoredIndex>> candidates =
        scores.size() > 0 ? CandidatesFromMatrix(scores, 32) : std::vector<std::vector<ScoredIndex>>{};
    return BridgeViewGraph(candidates, ids, options, verify, &tried, &verified);
  }
};

TEST(ViewGraphBridging, GapDistancesGrowGeometrically) {
  EXPECT_EQ(GapDistances(20), (std::vector<int>{2, 3, 4, 6, 8, 12, 16}));
  EXPECT_EQ(GapDistances(2), (std::vector<int>{2}));
}

TEST(ViewGraphBridging, BridgesAGapInTimeWithSeveralPairs) {
  // Two stretches; across the cut, frames 45..49 see what frames 20..24 later see.
  BridgeCase s(100, [](int i, int j) {
    if ((i < 50) == (j < 50)) return j - i <= 3;
    return i >= 45 && j - i >= 20 && j - i <= 24;
  });
  ASSERT_EQ(s.NumComponents(), 2);
  const auto report = s.Bridge(Eigen::MatrixXf());
  EXPECT_EQ(report.num_components_before, 2);
  EXPECT_EQ(report.largest_component_before, 50);
  EXPECT_EQ(report.num_components_after, 1);
  EXPECT_EQ(report.largest_component_after, 100);
  // Growing around the first bridges found every bridge pair (5 x 5 block of 25).
  int bridges = 0;
  for (int i = 45; i < 50; ++i) {
    for (int j = 65; j < 74; ++j) bridges += s.verified.Contains(i, j);
  }
  EXPECT_EQ(bridges, 25);
  EXPECT_EQ(report.num_tried, s.calls);
  EXPECT_LT(report.num_tried, 400u);
}

TEST(ViewGraphBridging, WeakFrameGetsItsOwnBestCandidates) {
  // Frame 70 is cut off in time (its neighbours never match it) but sees what frame 10 sees.
  auto truth = [](int i, int j) {
    if (i == 70 || j == 70) return (i == 10 && j == 70);
    return j - i <= 3;
  };
  BridgeCase s(100, truth);
  Eigen::MatrixXf scores = Eigen::MatrixXf::Constant(100, 100, 0.1f);
  // A strong loop elsewhere would fill a global top-k; frame 70's best is (10, 70).
  scores.block(0, 90, 10, 10).setConstant(0.9f);
  scores(10, 70) = scores(70, 10) = 0.5f;
  const auto report = s.Bridge(scores);
  EXPECT_TRUE(s.verified.Contains(10, 70));
  EXPECT_EQ(report.num_components_after, 1);
}

TEST(ViewGraphBridging, DeadStretchEndsQuickly) {
  // Frames 40..59 are black: nothing links them, and no bridge exists across them.
  auto truth = [](int i, int j) {
    if ((i >= 40 && i < 60) || (j >= 40 && j < 60)) return false;
    return j - i <= 3;
  };
  BridgeCase s(100, truth);
  Eigen::MatrixXf scores = Eigen::MatrixXf::Constant(100, 100, 0.1f);
  const auto report = s.Bridge(scores);
  EXPECT_EQ(report.num_verified, 0u);
  EXPECT_EQ(report.num_rounds, 1);
  EXPECT_EQ(report.num_components_after, report.num_components_before);
  // One round: gap pairs around two boundaries plus five candidates per weak frame.
  EXPECT_LT(report.num_tried, 2u * 2 * 8 * 14 + 70u * 5);
}

TEST(ViewGraphBridging, NothingToDoOnAConnectedGraph) {
  BridgeCase s(50, [](int i, int j) { return j - i <= 3; });
  const auto report = s.Bridge(Eigen::MatrixXf::Constant(50, 50, 0.2f));
  EXPECT_EQ(report.num_tried, 0u);
  EXPECT_EQ(report.num_components_after, 1);
}

}  // namespace
}  // namespace loopsfm
