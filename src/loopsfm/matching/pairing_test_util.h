#pragma once
// Test helpers of pair selection: index pair sets from simple rules, and similarity candidates
// from a dense test matrix, as ImageDatabase::Candidates gives them for a real one.

#include <algorithm>
#include <cstdlib>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/matching/pair_set.h"
#include "loopsfm/retrieval/image_database.h"

namespace loopsfm {

// Per frame, its best `k` partners more than min_gap indices away (best first, ties by index).
inline std::vector<std::vector<ScoredIndex>> CandidatesFromMatrix(const Eigen::MatrixXf& scores,
                                                                  int k, int min_gap = 0) {
  const int n = static_cast<int>(scores.rows());
  std::vector<std::vector<ScoredIndex>> candidates(n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      if (std::abs(i - j) > min_gap && scores(i, j) > 0) candidates[i].push_back({j, scores(i, j)});
    }
    auto& list = candidates[i];
    std::sort(list.begin(), list.end(), [](const ScoredIndex& a, const ScoredIndex& b) {
      return a.score != b.score ? a.score > b.score : a.index < b.index;
    });
    if (static_cast<int>(list.size()) > k) list.resize(k);
  }
  return candidates;
}

// Every pair {i, i + d} for d in [1, max_distance], added to each set given.
inline void InsertBand(int n, int max_distance, std::vector<IndexPairSet*> sets) {
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n && j <= i + max_distance; ++j) {
      for (IndexPairSet* set : sets) set->Insert(i, j);
    }
  }
}

}  // namespace loopsfm
