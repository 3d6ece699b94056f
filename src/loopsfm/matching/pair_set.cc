#include "loopsfm/matching/pair_set.h"

#include <algorithm>

#include "loopsfm/util/errors.h"

namespace loopsfm {

bool IndexPairSet::Contains(int i, int j) const {
  if (i == j || i < 0 || j < 0 || i >= NumFrames() || j >= NumFrames()) return false;
  return keys_.count(Key(i, j)) > 0;
}

bool IndexPairSet::Insert(int i, int j) {
  LOOPSFM_CHECK(i != j && i >= 0 && j >= 0 && i < NumFrames() && j < NumFrames());
  if (!keys_.insert(Key(i, j)).second) return false;
  partners_[i].push_back(j);
  partners_[j].push_back(i);
  return true;
}

std::vector<std::pair<int, int>> IndexPairSet::SortedPairs() const {
  std::vector<std::pair<int, int>> pairs;
  pairs.reserve(keys_.size());
  for (const uint64_t key : keys_) {
    pairs.emplace_back(static_cast<int>(key >> 32), static_cast<int>(key & 0xffffffffu));
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

}  // namespace loopsfm
