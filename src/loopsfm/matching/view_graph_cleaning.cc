#include "loopsfm/matching/view_graph_cleaning.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <set>
#include <tuple>
#include <unordered_set>
#include <utility>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/graph.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// The usable edges with nodes as dense indices (in increasing id order), each unordered pair
// once.
struct Graph {
  std::vector<image_t> ids;
  // Per graph edge: its index in the input and its node indices, first < second.
  std::vector<int> input_edge;
  std::vector<std::pair<int, int>> nodes;
  // Per node: (neighbour, graph edge), sorted by neighbour.
  std::vector<std::vector<std::pair<int, int>>> neighbours;

  int NumNodes() const { return static_cast<int>(ids.size()); }
  int NumEdges() const { return static_cast<int>(input_edge.size()); }
};

Graph BuildGraph(const std::vector<RelativeRotation>& edges, int* num_ignored) {
  Graph graph;
  std::unordered_set<uint64_t> seen;
  std::vector<int> usable;
  for (size_t e = 0; e < edges.size(); ++e) {
    const RelativeRotation& edge = edges[e];
    const uint64_t low = std::min(edge.node1, edge.node2);
    const uint64_t high = std::max(edge.node1, edge.node2);
    if (low == high || !(std::isfinite(edge.weight) && edge.weight > 0.0) ||
        !seen.insert((low << 32) | high).second) {
      ++*num_ignored;
      continue;
    }
    usable.push_back(static_cast<int>(e));
    graph.ids.push_back(edge.node1);
    graph.ids.push_back(edge.node2);
  }
  std::sort(graph.ids.begin(), graph.ids.end());
  graph.ids.erase(std::unique(graph.ids.begin(), graph.ids.end()), graph.ids.end());
  const auto index_of = [&](image_t id) {
    return static_cast<int>(std::lower_bound(graph.ids.begin(), graph.ids.end(), id) -
                            graph.ids.begin());
  };
  graph.neighbours.resize(graph.ids.size());
  for (int e : usable) {
    const int a = index_of(edges[e].node1);
    const int b = index_of(edges[e].node2);
    const int g = graph.NumEdges();
    graph.input_edge.push_back(e);
    graph.nodes.push_back({std::min(a, b), std::max(a, b)});
    graph.neighbours[a].push_back({b, g});
    graph.neighbours[b].push_back({a, g});
  }
  for (auto& list : graph.neighbours) std::sort(list.begin(), list.end());
  return graph;
}

struct Triangle {
  std::array<int, 3> edges;  // graph edges
  bool passes = false;
};

// Every triangle once, as (u, v, w) with u < v < w: for each edge (u, v), the common
// neighbours w > v of u and v (a merge of the two sorted lists).
std::vector<Triangle> FindTriangles(const Graph& graph, const std::vector<RelativeRotation>& edges,
                                    double max_loop_error_deg) {
  std::vector<Triangle> triangles;
  for (int g = 0; g < graph.NumEdges(); ++g) {
    const auto [u, v] = graph.nodes[g];
    const auto& nu = graph.neighbours[u];
    const auto& nv = graph.neighbours[v];
    auto iu = std::upper_bound(nu.begin(), nu.end(), std::make_pair(v, graph.NumEdges()));
    auto iv = std::upper_bound(nv.begin(), nv.end(), std::make_pair(v, graph.NumEdges()));
    while (iu != nu.end() && iv != nv.end()) {
      if (iu->first < iv->first) {
        ++iu;
      } else if (iv->first < iu->first) {
        ++iv;
      } else {
        Triangle triangle;
        triangle.edges = {g, iu->second, iv->second};
        triangle.passes =
            LoopErrorDegrees(edges[graph.input_edge[g]], edges[graph.input_edge[iu->second]],
                             edges[graph.input_edge[iv->second]]) <= max_loop_error_deg;
        triangles.push_back(triangle);
        ++iu;
        ++iv;
      }
    }
  }
  return triangles;
}

// Drops the edges that fail all their triangles, then the rest worst first (see
// view_graph_cleaning.h); returns the dropped flags per graph edge.
std::vector<bool> DropByTriangles(int num_edges, const std::vector<Triangle>& triangles,
                                  const std::vector<double>& edge_weight,
                                  double min_pass_fraction) {
  std::vector<std::vector<int>> triangles_of_edge(num_edges);
  std::vector<double> num_pass(num_edges, 0), num_fail(num_edges, 0);
  // What triangle t says about its edge e weighs as the weaker of its other two edges.
  const auto say = [&](size_t t, int e) {
    double weight = std::numeric_limits<double>::infinity();
    for (int other : triangles[t].edges) {
      if (other != e) weight = std::min(weight, edge_weight[other]);
    }
    return weight;
  };
  for (size_t t = 0; t < triangles.size(); ++t) {
    for (int e : triangles[t].edges) {
      triangles_of_edge[e].push_back(static_cast<int>(t));
      (triangles[t].passes ? num_pass : num_fail)[e] += say(t, e);
    }
  }
  std::vector<bool> dropped(num_edges, false);
  std::vector<bool> alive(triangles.size(), true);
  // Ordered worst first: smallest passing fraction, then most failing triangles, then index.
  using Key = std::tuple<double, double, int>;
  const auto key = [&](int e) {
    return Key(num_pass[e] / (num_pass[e] + num_fail[e]), -num_fail[e], e);
  };
  const auto candidate = [&](int e) {
    return !dropped[e] && num_fail[e] > 0 &&
           num_pass[e] < min_pass_fraction * (num_pass[e] + num_fail[e]);
  };
  // Holds the key of every candidate once the first pass is done.
  std::set<Key> queue;
  const auto drop = [&](int e) {
    if (candidate(e)) queue.erase(key(e));
    dropped[e] = true;
    for (int t : triangles_of_edge[e]) {
      if (!alive[t]) continue;
      alive[t] = false;
      for (int other : triangles[t].edges) {
        if (other == e || dropped[other]) continue;
        if (candidate(other)) queue.erase(key(other));
        (triangles[t].passes ? num_pass : num_fail)[other] -= say(t, other);
        if (candidate(other)) queue.insert(key(other));
      }
    }
  };
  std::vector<int> never_pass;
  for (int e = 0; e < num_edges; ++e) {
    if (num_pass[e] == 0 && num_fail[e] > 0) never_pass.push_back(e);
  }
  for (int e : never_pass) drop(e);
  for (int e = 0; e < num_edges; ++e) {
    if (candidate(e)) queue.insert(key(e));
  }
  while (!queue.empty()) drop(std::get<2>(*queue.begin()));
  return dropped;
}

// The rotation cam_to_from_cam_from measured by an edge between the two nodes.
Eigen::Quaterniond Between(const RelativeRotation& edge, image_t from, image_t to) {
  LOOPSFM_CHECK((edge.node1 == from && edge.node2 == to) ||
                (edge.node1 == to && edge.node2 == from));
  return edge.node1 == from ? edge.cam2_from_cam1.normalized()
                            : edge.cam2_from_cam1.normalized().conjugate();
}

}  // namespace

void ViewGraphCleaningOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(
      std::isfinite(max_loop_error_deg) && max_loop_error_deg > 0.0 && max_loop_error_deg < 180.0,
      "max_loop_error_deg must be in (0, 180) degrees, got {}", max_loop_error_deg);
  LOOPSFM_REQUIRE_OPTION(min_pass_fraction > 0.0 && min_pass_fraction <= 1.0,
                         "min_pass_fraction must be in (0, 1], got {}", min_pass_fraction);
}

double LoopErrorDegrees(const RelativeRotation& a, const RelativeRotation& b,
                        const RelativeRotation& c) {
  const image_t i = a.node1;
  const image_t j = a.node2;
  const image_t k = (b.node1 != i && b.node1 != j) ? b.node1 : b.node2;
  const bool b_touches_j = b.node1 == j || b.node2 == j;
  const RelativeRotation& jk = b_touches_j ? b : c;
  const RelativeRotation& ki = b_touches_j ? c : b;
  return RotationAngleDegrees(Between(ki, k, i) * Between(jk, j, k) * Between(a, i, j));
}

ViewGraphCleaningResult CleanViewGraph(const std::vector<RelativeRotation>& edges,
                                       const ViewGraphCleaningOptions& options) {
  options.Check();
  const Timer timer;
  ViewGraphCleaningResult result;
  ViewGraphCleaningReport& report = result.report;
  report.num_input_edges = static_cast<int>(edges.size());
  const Graph graph = BuildGraph(edges, &report.num_ignored_edges);
  const std::vector<Triangle> triangles = FindTriangles(graph, edges, options.max_loop_error_deg);
  report.num_triangles = static_cast<int>(triangles.size());
  std::vector<bool> in_triangle(graph.NumEdges(), false);
  for (const Triangle& triangle : triangles) {
    if (!triangle.passes) ++report.num_failed_triangles;
    for (int e : triangle.edges) in_triangle[e] = true;
  }
  std::vector<double> edge_weight(graph.NumEdges(), 1.0);
  if (options.weigh_triangles) {
    for (int g = 0; g < graph.NumEdges(); ++g) edge_weight[g] = edges[graph.input_edge[g]].weight;
  }
  const std::vector<bool> dropped =
      DropByTriangles(graph.NumEdges(), triangles, edge_weight, options.min_pass_fraction);

  std::vector<int> kept;
  std::vector<std::pair<int, int>> kept_pairs;
  for (int g = 0; g < graph.NumEdges(); ++g) {
    if (!in_triangle[g]) ++report.num_edges_in_no_triangle;
    if (dropped[g]) {
      ++report.num_dropped_by_triangles;
      continue;
    }
    kept.push_back(g);
    kept_pairs.push_back(graph.nodes[g]);
  }
  const GraphComponents components = ConnectedComponents(graph.NumNodes(), kept_pairs);
  std::vector<bool> node_kept(graph.NumNodes(), false);
  for (size_t k = 0; k < kept.size(); ++k) {
    if (options.keep_largest_component && components.label[kept_pairs[k].first] != 0) {
      ++report.num_dropped_outside_component;
      continue;
    }
    result.kept_edges.push_back(graph.input_edge[kept[k]]);
    node_kept[kept_pairs[k].first] = node_kept[kept_pairs[k].second] = true;
  }
  std::sort(result.kept_edges.begin(), result.kept_edges.end());
  report.num_edges = static_cast<int>(result.kept_edges.size());
  report.num_nodes = static_cast<int>(std::count(node_kept.begin(), node_kept.end(), true));
  report.time_s = timer.ElapsedSeconds();
  return result;
}

}  // namespace loopsfm
