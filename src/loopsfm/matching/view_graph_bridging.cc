#include "loopsfm/matching/view_graph_bridging.h"

#include <algorithm>

#include "loopsfm/math/graph.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

void ViewGraphBridgingOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_num_partners >= 0, "bridging: minimum partners must not be negative, got {}",
                         min_num_partners);
  LOOPSFM_REQUIRE_OPTION(gap_reach >= 1, "bridging: gap reach must be at least 1 frame, got {}", gap_reach);
  LOOPSFM_REQUIRE_OPTION(max_gap_frames >= 2, "bridging: largest gap distance must be at least 2, got {}",
                         max_gap_frames);
  LOOPSFM_REQUIRE_OPTION(num_candidates_per_frame >= 0,
                         "bridging: candidates per frame must not be negative, got {}",
                         num_candidates_per_frame);
  LOOPSFM_REQUIRE_OPTION(max_rounds >= 1, "bridging: at least one round, got {}", max_rounds);
  LOOPSFM_REQUIRE_OPTION(max_fruitless_rounds >= 1, "bridging: fruitless rounds must be at least 1, got {}",
                         max_fruitless_rounds);
}

std::vector<int> GapDistances(int max_distance) {
  std::vector<int> distances;
  for (int p = 2; p <= max_distance; p *= 2) {
    distances.push_back(p);
    if (p + p / 2 <= max_distance && p >= 2) distances.push_back(p + p / 2);
  }
  std::sort(distances.begin(), distances.end());
  distances.erase(std::unique(distances.begin(), distances.end()), distances.end());
  return distances;
}

namespace {

struct Proposals {
  explicit Proposals(const IndexPairSet& tried) : tried_(tried), proposed_(tried.NumFrames()) {}
  void Add(int i, int j) {
    const int n = tried_.NumFrames();
    if (i == j || i < 0 || j < 0 || i >= n || j >= n) return;
    if (i > j) std::swap(i, j);
    if (tried_.Contains(i, j) || proposed_.Contains(i, j)) return;
    proposed_.Insert(i, j);
    pairs.push_back({i, j});
  }
  std::vector<std::pair<int, int>> pairs;

 private:
  const IndexPairSet& tried_;
  IndexPairSet proposed_;
};

GraphComponents ComponentsOf(const IndexPairSet& verified) {
  return ConnectedComponents(verified.NumFrames(), verified.SortedPairs());
}

}  // namespace

ViewGraphBridgingReport BridgeViewGraph(const std::vector<std::vector<ScoredIndex>>& candidates,
                                        const std::vector<image_t>& ordered_ids,
                                        const ViewGraphBridgingOptions& options,
                                        const VerifyPairsFn& verify, IndexPairSet* tried,
                                        IndexPairSet* verified) {
  options.Check();
  const int n = static_cast<int>(ordered_ids.size());
  LOOPSFM_CHECK(tried->NumFrames() == n && verified->NumFrames() == n);
  LOOPSFM_CHECK(candidates.empty() || static_cast<int>(candidates.size()) == n);
  const std::vector<int> distances = GapDistances(options.max_gap_frames);

  ViewGraphBridgingReport report;
  GraphComponents components = ComponentsOf(*verified);
  report.num_components_before = components.NumComponents();
  report.largest_component_before = components.LargestSize();
  std::vector<std::pair<int, int>> last_verified;
  // Rounds in which a frame's own candidates all failed: after max_fruitless_rounds the frame
  // (a black or blurred frame, say) gets none any more.
  std::vector<int> fruitless(n, 0);
  std::vector<std::vector<int>> candidates_of(n);
  for (int round = 0; round < options.max_rounds; ++round) {
    Proposals proposals(*tried);
    // Growing around the bridges verified in the round before.
    for (const auto& [i, j] : last_verified) {
      proposals.Add(i - 1, j);
      proposals.Add(i + 1, j);
      proposals.Add(i, j - 1);
      proposals.Add(i, j + 1);
    }
    // Across gaps in time between components.
    for (int b = 0; b + 1 < n; ++b) {
      if (components.label[b] == components.label[b + 1]) continue;
      for (int i = std::max(0, b - options.gap_reach + 1); i <= b; ++i) {
        for (int d : distances) {
          if (i + d < n && components.label[i + d] != components.label[i]) proposals.Add(i, i + d);
        }
      }
      for (int j = b + 1; j < std::min(n, b + 1 + options.gap_reach); ++j) {
        for (int d : distances) {
          if (j - d >= 0 && components.label[j - d] != components.label[j]) proposals.Add(j - d, j);
        }
      }
    }
    // Weak frames' own best candidates, other components first.
    if (!candidates.empty() && options.num_candidates_per_frame > 0) {
      for (int i = 0; i < n; ++i) {
        const int partners = static_cast<int>(verified->Partners(i).size());
        if (components.label[i] == 0 && partners >= options.min_num_partners) continue;
        if (fruitless[i] >= options.max_fruitless_rounds) continue;
        std::vector<std::pair<float, int>> ranked;
        for (const ScoredIndex& c : candidates[i]) {
          if (c.index == i || tried->Contains(i, c.index)) continue;
          const bool other = components.label[c.index] != components.label[i];
          // Candidates in other components rank above those in the frame's own.
          ranked.push_back({c.score + (other ? 2.0f : 0.0f), c.index});
        }
        const size_t k = std::min<size_t>(ranked.size(), options.num_candidates_per_frame);
        std::partial_sort(ranked.begin(), ranked.begin() + k, ranked.end(),
                          [](const auto& a, const auto& b) {
                            return a.first != b.first ? a.first > b.first : a.second < b.second;
                          });
        candidates_of[i].clear();
        for (size_t c = 0; c < k; ++c) {
          proposals.Add(i, ranked[c].second);
          candidates_of[i].push_back(ranked[c].second);
        }
      }
    }
    if (proposals.pairs.empty()) break;

    std::vector<ImagePair> pairs;
    for (const auto& [i, j] : proposals.pairs) pairs.emplace_back(ordered_ids[i], ordered_ids[j]);
    const std::vector<bool> ok = verify(pairs);
    LOOPSFM_CHECK(ok.size() == pairs.size());
    ++report.num_rounds;
    report.num_tried += pairs.size();
    last_verified.clear();
    for (size_t m = 0; m < pairs.size(); ++m) {
      const auto [i, j] = proposals.pairs[m];
      tried->Insert(i, j);
      if (!ok[m]) continue;
      verified->Insert(i, j);
      last_verified.push_back({i, j});
    }
    report.num_verified += last_verified.size();
    for (int i = 0; i < n; ++i) {
      if (candidates_of[i].empty()) continue;
      const bool any = std::any_of(candidates_of[i].begin(), candidates_of[i].end(),
                                   [&](int j) { return verified->Contains(i, j); });
      fruitless[i] = any ? 0 : fruitless[i] + 1;
      candidates_of[i].clear();
    }
    if (last_verified.empty()) break;
    components = ComponentsOf(*verified);
  }
  components = ComponentsOf(*verified);
  report.num_components_after = components.NumComponents();
  report.largest_component_after = components.LargestSize();
  return report;
}

}  // namespace loopsfm
