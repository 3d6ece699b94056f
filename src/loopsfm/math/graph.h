#pragma once
// Graph algorithms over small dense or edge-list graphs with vertices 0..n-1.

#include <algorithm>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/math/union_find.h"

namespace loopsfm {

// Connected components: label[v] in 0..k-1, components numbered by decreasing size (0 is the
// largest; ties by smallest vertex), so the labelling does not depend on edge order.
struct GraphComponents {
  std::vector<int> label;
  std::vector<int> sizes;
  int NumComponents() const { return static_cast<int>(sizes.size()); }
  int LargestSize() const { return sizes.empty() ? 0 : sizes[0]; }
};

inline GraphComponents ConnectedComponents(int n, const std::vector<std::pair<int, int>>& edges) {
  UnionFind sets(static_cast<size_t>(n));
  for (const auto& [a, b] : edges) sets.Union(static_cast<size_t>(a), static_cast<size_t>(b));
  // Components by (size descending, smallest vertex ascending).
  std::vector<std::pair<int, int>> order;  // (-size, first vertex) per root
  std::vector<int> first_of_root(n, -1);
  for (int v = 0; v < n; ++v) {
    const int root = static_cast<int>(sets.Find(v));
    if (first_of_root[root] < 0) {
      first_of_root[root] = v;
      order.push_back({-static_cast<int>(sets.SetSize(v)), v});
    }
  }
  std::sort(order.begin(), order.end());
  std::vector<int> component_of_root(n, -1);
  GraphComponents result;
  result.label.assign(n, -1);
  for (size_t c = 0; c < order.size(); ++c) {
    component_of_root[sets.Find(order[c].second)] = static_cast<int>(c);
    result.sizes.push_back(-order[c].first);
  }
  for (int v = 0; v < n; ++v) result.label[v] = component_of_root[sets.Find(v)];
  return result;
}

// Components of a symmetric adjacency matrix (only the upper triangle is read).
template <typename Derived>
GraphComponents ConnectedComponents(const Eigen::DenseBase<Derived>& adjacency) {
  const int n = static_cast<int>(adjacency.rows());
  std::vector<std::pair<int, int>> edges;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (adjacency(i, j)) edges.push_back({i, j});
    }
  }
  return ConnectedComponents(n, edges);
}

}  // namespace loopsfm
