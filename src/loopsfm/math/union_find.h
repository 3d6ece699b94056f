#pragma once
// Disjoint sets over dense indices 0..n-1 with path halving and union by size.

#include <cstddef>
#include <numeric>
#include <vector>

namespace loopsfm {

class UnionFind {
 public:
  explicit UnionFind(size_t n = 0) { Reset(n); }

  void Reset(size_t n) {
    parent_.resize(n);
    std::iota(parent_.begin(), parent_.end(), size_t{0});
    size_.assign(n, 1);
  }
  size_t Size() const { return parent_.size(); }

  size_t Find(size_t x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }

  // Returns the new root, or the common root when already joined.
  size_t Union(size_t a, size_t b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return a;
    if (size_[a] < size_[b]) std::swap(a, b);
    parent_[b] = a;
    size_[a] += size_[b];
    return a;
  }

  size_t SetSize(size_t x) { return size_[Find(x)]; }

 private:
  std::vector<size_t> parent_;
  std::vector<size_t> size_;
};

}  // namespace loopsfm
