#include "loopsfm/matching/guided_pairing.h"

#include <gtest/gtest.h>

#include "loopsfm/math/random.h"
#include "loopsfm/matching/pairing_test_util.h"

namespace loopsfm {
namespace {

// Loop candidates per frame, as the pipeline keeps them.
constexpr int kCandidates = 32;

// 100 frames; frames 90..99 revisit frames 0..9. A pair truly matches when the frames are
// within 2 of each other along the path or across the loop.
bool TrulyMatches(int i, int j) {
  if (std::abs(i - j) <= 2) return true;
  const int a = std::min(i, j), b = std::max(i, j);
  return a < 10 && b >= 90 && std::abs(a - (b - 90)) <= 2;
}

// A symmetric similarity matrix: pairs that truly match score in [min_true_score, 1), the
// others in [0, 0.3).
template <typename Truth>
Eigen::MatrixXf ScoresFromTruth(int n, const Truth& truth, double min_true_score, uint64_t seed) {
  Eigen::MatrixXf scores(n, n);
  Random random(seed);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      scores(i, j) = truth(i, j) ? static_cast<float>(random.UniformReal(min_true_score, 1.0))
                                 : static_cast<float>(random.UniformReal(0.0, 0.3));
    }
  }
  return (scores + scores.transpose()) / 2;
}

TEST(GuidedPairing, RegionGrowingCoversTheLoopBlockAndStops) {
  const int n = 100;
  std::vector<image_t> ids(n);
  for (int i = 0; i < n; ++i) ids[i] = i + 1;
  // Scores like a vocabulary tree's: true pairs score high, but only a third of the loop
  // pairs stand out; near misses (frames 3-4 apart) score in between.
  Random random(3);
  Eigen::MatrixXf scores(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const int a = std::min(i, j), b = std::max(i, j);
      float score = static_cast<float>(random.UniformReal(0, 0.1));
      if (std::abs(a - b) <= 4) score = static_cast<float>(random.UniformReal(0.2, 0.4));
      if (TrulyMatches(a, b) && (b < 90 || (a + b) % 3 == 0)) score = static_cast<float>(random.UniformReal(0.5, 1.0));
      scores(i, j) = score;
    }
  }
  scores = (scores + scores.transpose()).eval() / 2;
  // Sequential neighbours matched beforehand.
  IndexPairSet tried(n), verified(n);
  InsertBand(n, 2, {&tried, &verified});
  size_t calls = 0;
  auto verify = [&](const std::vector<ImagePair>& pairs) {
    ++calls;
    std::vector<bool> ok;
    for (const ImagePair& p : pairs) ok.push_back(TrulyMatches(p.image_id1 - 1, p.image_id2 - 1));
    return ok;
  };
  GuidedPairingOptions options;
  options.num_proposals = 20;
  options.max_loop_partners = 0;  // every loop pair, for recall
  const GuidedPairingReport report = RunGuidedPairing(
      CandidatesFromMatrix(scores, kCandidates, options.min_frame_gap), ids, options, verify,
      &tried, &verified);

  // Every true loop pair is found.
  int loop_pairs = 0, found = 0;
  for (int a = 0; a < 10; ++a) {
    for (int b = 90; b < n; ++b) {
      if (!TrulyMatches(a, b)) continue;
      ++loop_pairs;
      found += verified.Contains(a, b);
    }
  }
  EXPECT_EQ(found, loop_pairs);
  // It stopped long before trying everything (4950 pairs).
  EXPECT_LT(report.num_tried, 600u);
  EXPECT_EQ(report.rounds.size(), calls);
  EXPECT_GE(report.rounds.size(), 2u);
  // Proposals by score went on until a round's mostly failed; after that round, none.
  size_t last_scoring = 0;
  for (size_t r = 0; r < report.rounds.size(); ++r) {
    if (report.rounds[r].num_from_scores > 0) last_scoring = r;
  }
  const auto& last = report.rounds[last_scoring];
  EXPECT_GT(last.num_from_scores - last.num_verified_from_scores, 0.7 * last.num_from_scores);
  // Later rounds propose by score only as many pairs as the round before verified by score.
  for (size_t r = 1; r <= last_scoring; ++r) {
    EXPECT_LE(report.rounds[r].num_from_scores, report.rounds[r - 1].num_verified_from_scores);
  }
  // Region growing ran dry: every neighbour of a verified loop pair was tried.
  for (int a = 0; a < 10; ++a) {
    for (int b = 90; b < n; ++b) {
      if (!verified.Contains(a, b)) continue;
      EXPECT_TRUE(tried.Contains(a + 1, b) && tried.Contains(a, b - 1) &&
                  (b + 1 >= n || tried.Contains(a, b + 1)))
          << a << ", " << b;
    }
  }
  EXPECT_GT(report.rounds[1].num_from_growing, 0u);
  // Nothing is tried twice: tried pairs = sequential + proposals.
  EXPECT_EQ(tried.Size(), 197u + report.num_tried);
}

// A slow revisit: frames 60..89 see what frames 0..29 saw, each within 6 frames of its
// counterpart, a band of 13 x 30 = 390 loop pairs. With a limit on loop partners, every
// revisiting frame still gets linked, at a fraction of the pairs.
TEST(GuidedPairing, LoopPartnerLimitThinsAWideBand) {
  const int n = 100;
  std::vector<image_t> ids(n);
  for (int i = 0; i < n; ++i) ids[i] = i + 1;
  auto truth = [](int a, int b) {
    if (a > b) std::swap(a, b);
    if (b - a <= 3) return true;
    return a < 30 && b >= 60 && b < 90 && std::abs(a - (b - 60)) <= 6;
  };
  const Eigen::MatrixXf scores = ScoresFromTruth(n, truth, /*min_true_score=*/0.4, /*seed=*/4);
  auto run = [&](int max_loop_partners, IndexPairSet* verified) {
    IndexPairSet tried(n);
    *verified = IndexPairSet(n);
    InsertBand(n, 3, {&tried, verified});
    auto verify = [&](const std::vector<ImagePair>& pairs) {
      std::vector<bool> ok;
      for (const ImagePair& p : pairs) ok.push_back(truth(p.image_id1 - 1, p.image_id2 - 1));
      return ok;
    };
    GuidedPairingOptions options;
    options.num_proposals = 20;
    options.min_frame_gap = 3;
    options.max_loop_partners = max_loop_partners;
    return RunGuidedPairing(CandidatesFromMatrix(scores, kCandidates, options.min_frame_gap), ids,
                            options, verify, &tried, verified);
  };
  auto loop_partners = [&](const IndexPairSet& verified, int i) {
    int count = 0;
    for (int j = 0; j < n; ++j) count += verified.Contains(i, j) && std::abs(i - j) > 3;
    return count;
  };
  IndexPairSet all, thin;
  const GuidedPairingReport full = run(0, &all);
  const GuidedPairingReport thinned = run(3, &thin);
  auto band = [](const IndexPairSet& verified) {
    int count = 0;
    for (int a = 0; a < 30; ++a) {
      for (int b = 60; b < 90; ++b) count += verified.Contains(a, b);
    }
    return count;
  };
  // Without a limit, region growing fills most of the band (measured: 348 of 390).
  EXPECT_GT(band(all), 300);
  EXPECT_LT(band(thin), band(all) / 2);
  for (int i : {0, 15, 29, 60, 75, 89}) EXPECT_GE(loop_partners(thin, i), 2) << i;
  for (int i = 0; i < 30; ++i) EXPECT_GE(loop_partners(thin, i), 1) << i;
  for (int i = 60; i < 90; ++i) EXPECT_GE(loop_partners(thin, i), 1) << i;
  // Measured: 148 pairs tried against 435.
  EXPECT_LT(thinned.num_tried, full.num_tried / 2);
}

// Pairs the sequential part covered do not count as loop partners, and pairs verified by an
// earlier run do: a frame whose far sequential steps verified still gets its loop pairs, and
// running again on the finished masks (a resumed run) tries little: one round of score
// proposals for the frames still below the limit (the stop rule's state is not stored).
TEST(GuidedPairing, SequentialPairsAreNotLoopPartnersAndResumingTriesNothing) {
  const int n = 60;
  std::vector<image_t> ids(n);
  for (int i = 0; i < n; ++i) ids[i] = static_cast<image_t>(i + 1);
  // Frames 0-9 see frames 50-59 again; every frame also verifies with i + 8 and i + 16.
  auto truth = [](int a, int b) {
    if (a > b) std::swap(a, b);
    if (b - a <= 3 || b - a == 8 || b - a == 16) return true;
    return a < 10 && b >= 50 && std::abs(a - (b - 50)) <= 3;
  };
  const Eigen::MatrixXf scores = ScoresFromTruth(n, truth, /*min_true_score=*/0.5, /*seed=*/5);
  IndexPairSet tried(n), verified(n), sequential(n);
  for (int i = 0; i < n; ++i) {
    for (int d : {1, 2, 3, 8, 16}) {
      if (i + d >= n) continue;
      tried.Insert(i, i + d);
      sequential.Insert(i, i + d);
      if (truth(i, i + d)) verified.Insert(i, i + d);
    }
  }
  auto verify = [&](const std::vector<ImagePair>& pairs) {
    std::vector<bool> ok;
    for (const ImagePair& p : pairs) ok.push_back(truth(p.image_id1 - 1, p.image_id2 - 1));
    return ok;
  };
  GuidedPairingOptions options;
  options.num_proposals = 20;
  options.min_frame_gap = 3;
  options.max_loop_partners = 2;
  const auto candidates = CandidatesFromMatrix(scores, kCandidates, options.min_frame_gap);
  // Counting the i + 8 and i + 16 pairs, every frame would start saturated.
  IndexPairSet tried_counting = tried, verified_counting = verified;
  EXPECT_EQ(RunGuidedPairing(candidates, ids, options, verify, &tried_counting, &verified_counting).num_verified, 0u);
  const GuidedPairingReport first = RunGuidedPairing(candidates, ids, options, verify, &tried, &verified, &sequential);
  EXPECT_GT(first.num_verified, 10u);
  for (int a = 0; a < 10; ++a) {
    int partners = 0;
    for (int b = 50; b < n; ++b) partners += verified.Contains(a, b);
    EXPECT_GE(partners, 1) << a;
  }
  const GuidedPairingReport resumed = RunGuidedPairing(candidates, ids, options, verify, &tried, &verified, &sequential);
  EXPECT_LE(resumed.num_tried, static_cast<size_t>(options.num_proposals)) << first.num_tried;
}

TEST(GuidedPairing, RejectsBadOptions) {
  GuidedPairingOptions options;
  options.max_failure_ratio = 0;
  EXPECT_THROW(options.Check(), std::exception);
}

}  // namespace
}  // namespace loopsfm
