#include "loopsfm/matching/guided_pairing.h"

#include <algorithm>
#include <queue>

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

using BoolMatrix = Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic>;

struct IndexPair {
  int i, j;  // i < j
};

// The k best untried pairs (i < j), best first, ties by index for determinism.
// `skip(i, j)` leaves a pair out.
template <typename Skip>
std::vector<IndexPair> BestUntriedPairs(const Eigen::MatrixXf& scores, const BoolMatrix& tried,
                                        const BoolMatrix& proposed, int k, int min_gap,
                                        const Skip& skip) {
  using Entry = std::pair<float, std::pair<int, int>>;
  // Min-heap of the best k seen so far.
  auto worse = [](const Entry& a, const Entry& b) {
    if (a.first != b.first) return a.first > b.first;
    return a.second < b.second;
  };
  std::priority_queue<Entry, std::vector<Entry>, decltype(worse)> heap(worse);
  const int n = static_cast<int>(scores.rows());
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1 + min_gap; j < n; ++j) {
      if (tried(i, j) || proposed(i, j) || skip(i, j)) continue;
      const Entry entry{std::max(scores(i, j), scores(j, i)), {i, j}};
      if (static_cast<int>(heap.size()) < k) {
        heap.push(entry);
      } else if (worse(entry, heap.top())) {
        heap.pop();
        heap.push(entry);
      }
    }
  }
  std::vector<IndexPair> best;
  while (!heap.empty()) {
    best.push_back({heap.top().second.first, heap.top().second.second});
    heap.pop();
  }
  std::reverse(best.begin(), best.end());
  return best;
}

}  // namespace

GuidedPairingReport RunGuidedPairing(const Eigen::MatrixXf& scores,
                                     const std::vector<image_t>& image_ids,
                                     const GuidedPairingOptions& options,
                                     const VerifyPairsFn& verify, BoolMatrix* tried,
                                     BoolMatrix* verified, const BoolMatrix* sequential) {
  options.Check();
  const int n = static_cast<int>(image_ids.size());
  LOOPSFM_CHECK(scores.rows() == n && scores.cols() == n);
  LOOPSFM_CHECK(tried->rows() == n && verified->rows() == n);
  LOOPSFM_CHECK(sequential == nullptr || (sequential->rows() == n && sequential->cols() == n));
  GuidedPairingReport report;
  // Score proposals of the next round: k in the first, then as many as the previous round's
  // score proposals verified, until more than max_failure_ratio of a round's fail.
  int num_by_score = options.num_proposals > 0 ? options.num_proposals : n;

  // Verified partners beyond the sequential window, per frame.
  std::vector<int> loop_partners(n, 0);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      loop_partners[i] += (*verified)(i, j) && std::abs(i - j) > options.min_frame_gap &&
                          !(sequential != nullptr && (*sequential)(i, j));
    }
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
    BoolMatrix proposed = BoolMatrix::Constant(n, n, false);
    std::vector<IndexPair> proposals;
    auto propose = [&](int i, int j) {
      if (i == j || i < 0 || j < 0 || i >= n || j >= n) return false;
      if (i > j) std::swap(i, j);
      if ((*tried)(i, j) || proposed(i, j) || saturated(i, j)) return false;
      proposed(i, j) = true;
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
    if (num_by_score > 0) {
      for (const IndexPair& p : BestUntriedPairs(scores, *tried, proposed, num_by_score, options.min_frame_gap, saturated)) {
        stats.num_from_scores += propose(p.i, p.j);
      }
    }
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
      (*tried)(p.i, p.j) = (*tried)(p.j, p.i) = true;
      if (ok[m]) {
        (*verified)(p.i, p.j) = (*verified)(p.j, p.i) = true;
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
