#pragma once
// A set of unordered pairs {i, j} of frame indices (capture order): the pairs that pair
// selection tried, verified or covered. Memory grows with the pairs, which pair selection keeps
// to a few per frame, not with the square of the frames, and each frame's partners are at hand.

#include <cstddef>
#include <cstdint>
#include <unordered_set>
#include <utility>
#include <vector>

namespace loopsfm {

class IndexPairSet {
 public:
  explicit IndexPairSet(int num_frames = 0) : partners_(num_frames) {}

  int NumFrames() const { return static_cast<int>(partners_.size()); }
  size_t Size() const { return keys_.size(); }
  // False for i == j or an index out of range.
  bool Contains(int i, int j) const;
  // Adds {i, j} (i != j, both in [0, NumFrames())); false when it was there already.
  bool Insert(int i, int j);
  // The frames paired with i, in the order the pairs were added.
  const std::vector<int>& Partners(int i) const { return partners_[i]; }
  // Every pair once, as (i, j) with i < j, sorted.
  std::vector<std::pair<int, int>> SortedPairs() const;

 private:
  static uint64_t Key(int i, int j) {
    if (i > j) std::swap(i, j);
    return (static_cast<uint64_t>(static_cast<uint32_t>(i)) << 32) | static_cast<uint32_t>(j);
  }
  std::unordered_set<uint64_t> keys_;
  std::vector<std::vector<int>> partners_;
};

}  // namespace loopsfm
