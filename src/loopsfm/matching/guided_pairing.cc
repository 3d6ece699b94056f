#include "loopsfm/matching/guided_pairing.h"

#include <algorithm>
#include <cstdlib>

#include "loopsfm/util/errors.h"

namespace loopsfm {

void GuidedPairingOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(num_proposals >= 0, "proposals per round must not be negative, got {}",
                         num_proposals);
  LOOPSFM_REQUIRE_OPTION(max_failure_ratio > 0 && max_failure_ratio <= 1,
                         "failure ratio to stop at must be in (0, 1], got {}", max_failure_ratio);
  LOOPSFM_REQUIRE_OPTION(max_rounds >= 1, "at least one round, got {}", max_rounds);
  LOOPSFM_REQUIRE_OPTION(max_loop_partners >= 0, "loop partners must not be negative, got {}",
                         max_loop_partners);
  LOOPSFM_REQUIRE_OPTION(min_frame_gap >= 0, "minimum frame gap must not be negative, got {}",
                         min_frame_gap);
}

namespace {

struct IndexPair {
  int i, j;  // i < j
};

// The loop candidates as distinct pairs (i < j), best first (ties by index, for determinism); a
// pair listed by both of its frames takes the higher of the two scores.
std::vector<IndexPair> RankedCandidatePairs(const std::vector<std::vector<ScoredIndex>>& candidates,
                                            int min_gap) {
  struct Entry {
    float score;
    int i, j;
  };
  std::vector<Entry> entries;
  for (int i = 0; i < static_cast<int>(candidates.size()); ++i) {
    for (const ScoredIndex& c : candidates[i]) {
      if (std::abs(c.index - i) <= min_gap) continue;
      entries.push_back({c.score, std::min(i, c.index), std::max(i, c.index)});
    }
  }
  // Each pair once, with its best score: by pair, best score first, then by score.
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    return a.i != b.i ? a.i < b.i : a.j != b.j ? a.j < b.j : a.score > b.score;
  });
  entries.erase(std::unique(entries.begin(), entries.end(),
                            [](const Entry& a, const Entry& b) { return a.i == b.i && a.j == b.j; }),
                entries.end());
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    return a.score != b.score ? a.score > b.score : a.i != b.i ? a.i < b.i : a.j < b.j;
  });
  std::vector<IndexPair> ranked;
  ranked.reserve(entries.size());
  for (const Entry& e : entries) ranked.push_back({e.i, e.j});
  return ranked;
}

}  // namespace

GuidedPairingReport RunGuidedPairing(const std::vector<std::vector<ScoredIndex>>& candidates,
                                     const std::vector<image_t>& image_ids,
                                     const GuidedPairingOptions& options,
                                     const VerifyPairsFn& verify, IndexPairSet* tried,
                                     IndexPairSet* verified, const IndexPairSet* sequential) {
  options.Check();
  const int n = static_cast<int>(image_ids.size());
  LOOPSFM_CHECK(static_cast<int>(candidates.size()) == n);
  LOOPSFM_CHECK(tried->NumFrames() == n && verified->NumFrames() == n);
  LOOPSFM_CHECK(sequential == nullptr || sequential->NumFrames() == n);
  GuidedPairingReport report;
  const std::vector<IndexPair> ranked = RankedCandidatePairs(candidates, options.min_frame_gap);
  // Score proposals of the next round: k in the first, then as many as the previous round's
  // score proposals verified, until more than max_failure_ratio of a round's fail.
  int num_by_score = options.num_proposals > 0 ? options.num_proposals : n;

  // Verified partners beyond the sequential window, per frame.
  auto is_loop_pair = [&](int i, int j) {
    return std::abs(i - j) > options.min_frame_gap &&
           !(sequential != nullptr && sequential->Contains(i, j));
  };
  std::vector<int> loop_partners(n, 0);
  for (int i = 0; i < n; ++i) {
    for (const int j : verified->Partners(i)) loop_partners[i] += is_loop_pair(i, j);
  }
  // Proposals of the current round count as partners until verified or not, so one round's
  // growth along a wide band does not overshoot the limit.
  std::vector<int> pending(n, 0);
  auto saturated = [&](int i, int j) {
    const int k = options.max_loop_partners;
    return k > 0 && loop_partners[i] + pending[i] >= k && loop_partners[j] + pending[j] >= k;
  };

  // Region growing starts from the first round's verified proposals: pairs verified before
  // (sequential neighbours) would only grow along the diagonal, which sequential matching
  // already covers.
  std::vector<IndexPair> last_verified;

  for (int round = 0; round < options.max_rounds; ++round) {
    IndexPairSet proposed(n);
    std::vector<IndexPair> proposals;
    auto propose = [&](int i, int j) {
      if (i == j || i < 0 || j < 0 || i >= n || j >= n) return false;
      if (i > j) std::swap(i, j);
      if (tried->Contains(i, j) || proposed.Contains(i, j) || saturated(i, j)) return false;
      proposed.Insert(i, j);
      if (j - i > options.min_frame_gap) {
        ++pending[i];
        ++pending[j];
      }
      proposals.push_back({i, j});
      return true;
    };
    GuidedPairingRound stats;
    for (const IndexPair& p : last_verified) {
      const int di[4] = {-1, 1, 0, 0}, dj[4] = {0, 0, -1, 1};
      for (int d = 0; d < 4; ++d) stats.num_from_growing += propose(p.i + di[d], p.j + dj[d]);
    }
    const size_t first_from_scores = proposals.size();
    // The num_by_score best candidates neither tried, grown into nor saturated before this
    // round's score proposals (which then count as pending, as they are proposed).
    std::vector<IndexPair> best;
    for (size_t c = 0; c < ranked.size() && static_cast<int>(best.size()) < num_by_score; ++c) {
      const auto [i, j] = ranked[c];
      if (tried->Contains(i, j) || proposed.Contains(i, j) || saturated(i, j)) continue;
      best.push_back(ranked[c]);
    }
    for (const IndexPair& p : best) stats.num_from_scores += propose(p.i, p.j);
    if (proposals.empty()) break;

    std::vector<ImagePair> pairs;
    pairs.reserve(proposals.size());
    for (const IndexPair& p : proposals) pairs.emplace_back(image_ids[p.i], image_ids[p.j]);
    const std::vector<bool> ok = verify(pairs);
    LOOPSFM_CHECK(ok.size() == pairs.size());
    std::fill(pending.begin(), pending.end(), 0);
    last_verified.clear();
    for (size_t m = 0; m < proposals.size(); ++m) {
      const IndexPair& p = proposals[m];
      tried->Insert(p.i, p.j);
      if (ok[m]) {
        verified->Insert(p.i, p.j);
        last_verified.push_back(p);
        if (p.j - p.i > options.min_frame_gap) {
          ++loop_partners[p.i];
          ++loop_partners[p.j];
        }
        ++stats.num_verified;
        stats.num_verified_from_scores += m >= first_from_scores;
      }
    }
    report.num_tried += proposals.size();
    report.num_verified += stats.num_verified;
    report.rounds.push_back(stats);
    const size_t score_failures = stats.num_from_scores - stats.num_verified_from_scores;
    const bool scores_exhausted =
        stats.num_from_scores == 0 || score_failures > options.max_failure_ratio * stats.num_from_scores;
    num_by_score = scores_exhausted ? 0 : static_cast<int>(stats.num_verified_from_scores);
  }
  return report;
}

}  // namespace loopsfm
