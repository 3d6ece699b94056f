// The largest component and the initial trees of rotation averaging (rotation_averaging.h,
// step 1).
#include "loopsfm/estimators/rotation_averaging_internal.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <queue>
#include <tuple>

#include "loopsfm/math/graph.h"
#include "loopsfm/math/union_find.h"

namespace loopsfm {
namespace rotation_averaging_internal {
namespace {

bool UsableEdge(const RelativeRotation& edge) {
  return edge.node1 != edge.node2 && std::isfinite(edge.weight) && edge.weight > 0.0;
}

int HeaviestNode(const ComponentProblem& problem) {
  std::vector<double> total(problem.NumNodes(), 0.0);
  for (int e = 0; e < problem.NumEdges(); ++e) {
    total[problem.node1[e]] += problem.weight[e];
    total[problem.node2[e]] += problem.weight[e];
  }
  int best = 0;
  for (int k = 1; k < problem.NumNodes(); ++k) {
    if (total[k] > total[best]) best = k;
  }
  return best;
}

// The rotation of the other node of edge e that the rotation of `from` and the measurement
// give: R_2 = R_12 R_1, or R_1 = R_12^T R_2.
Eigen::Quaterniond Propagate(const ComponentProblem& problem, int e, int from,
                             const Eigen::Quaterniond& rotation_from) {
  const Eigen::Quaterniond& measured = problem.measured[e];
  return (problem.node1[e] == from ? measured * rotation_from
                                   : measured.conjugate() * rotation_from)
      .normalized();
}

int OtherNode(const ComponentProblem& problem, int e, int node) {
  return problem.node1[e] == node ? problem.node2[e] : problem.node1[e];
}

// Rotations propagated from the root along a maximum-weight spanning tree (Kruskal; ties go
// to the earlier edge).
std::vector<Eigen::Quaterniond> MaxWeightTreeRotations(const ComponentProblem& problem) {
  const int n = problem.NumNodes();
  std::vector<int> order(problem.NumEdges());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return problem.weight[a] > problem.weight[b]; });
  UnionFind sets(static_cast<size_t>(n));
  std::vector<std::vector<int>> tree_edges(n);
  for (int e : order) {
    const int a = problem.node1[e];
    const int b = problem.node2[e];
    if (sets.Find(a) == sets.Find(b)) continue;
    sets.Union(a, b);
    tree_edges[a].push_back(e);
    tree_edges[b].push_back(e);
  }
  std::vector<Eigen::Quaterniond> rotations(n, Eigen::Quaterniond::Identity());
  std::vector<bool> reached(n, false);
  std::queue<int> queue;
  queue.push(problem.root);
  reached[problem.root] = true;
  while (!queue.empty()) {
    const int v = queue.front();
    queue.pop();
    for (int e : tree_edges[v]) {
      const int other = OtherNode(problem, e, v);
      if (reached[other]) continue;
      rotations[other] = Propagate(problem, e, v, rotations[v]);
      reached[other] = true;
      queue.push(other);
    }
  }
  return rotations;
}

// How much agrees with a candidate rotation: the number of candidates within the agreement
// angle (itself included), then their total measurement weight.
using Support = std::pair<int, double>;

// The rotations an unplaced node's edges to placed nodes give it, each with its support.
class Candidates {
 public:
  void Add(const Eigen::Quaterniond& rotation, double weight, double agreement_rad) {
    Support own{1, weight};
    for (size_t j = 0; j < rotations_.size(); ++j) {
      if (rotations_[j].angularDistance(rotation) > agreement_rad) continue;
      own.first += 1;
      own.second += weights_[j];
      support_[j].first += 1;
      support_[j].second += weight;
    }
    rotations_.push_back(rotation);
    weights_.push_back(weight);
    support_.push_back(own);
    best_ = 0;
    for (size_t j = 1; j < support_.size(); ++j) {
      if (support_[j] > support_[best_]) best_ = j;
    }
  }
  // The best-supported rotation (ties: the earliest).
  const Eigen::Quaterniond& Best() const { return rotations_[best_]; }
  // How sure the best rotation is: its number of agreeing candidates, minus the number of
  // disagreeing ones, then its support weight (larger is surer).
  std::tuple<int, int, double> Confidence() const {
    if (support_.empty()) return {0, 0, 0.0};
    const Support& best = support_[best_];
    return {best.first, 2 * best.first - static_cast<int>(support_.size()), best.second};
  }

 private:
  std::vector<Eigen::Quaterniond> rotations_;
  std::vector<double> weights_;
  std::vector<Support> support_;
  size_t best_ = 0;
};

// Grows a tree from the root: the next node is the one whose best candidate rotation is the
// surest (Candidates::Confidence; ties: the smallest id), and it gets that rotation.
std::vector<Eigen::Quaterniond> ConsensusTreeRotations(const ComponentProblem& problem,
                                                       double agreement_rad) {
  const int n = problem.NumNodes();
  std::vector<std::vector<int>> incident(n);
  for (int e = 0; e < problem.NumEdges(); ++e) {
    incident[problem.node1[e]].push_back(e);
    incident[problem.node2[e]].push_back(e);
  }
  std::vector<Eigen::Quaterniond> rotations(n, Eigen::Quaterniond::Identity());
  std::vector<bool> placed(n, false);
  std::vector<Candidates> candidates(n);
  std::priority_queue<std::pair<std::tuple<int, int, double>, int>> queue;  // (confidence, -node)
  // `rotation` is a copy: the node's candidates are cleared here.
  const auto place = [&](int v, Eigen::Quaterniond rotation) {
    placed[v] = true;
    rotations[v] = rotation;
    candidates[v] = Candidates();
    for (int e : incident[v]) {
      const int other = OtherNode(problem, e, v);
      if (placed[other]) continue;
      candidates[other].Add(Propagate(problem, e, v, rotation), problem.weight[e], agreement_rad);
      queue.push({candidates[other].Confidence(), -other});
    }
  };
  place(problem.root, Eigen::Quaterniond::Identity());
  while (!queue.empty()) {
    const auto [confidence, negated] = queue.top();
    queue.pop();
    const int v = -negated;
    if (placed[v] || confidence != candidates[v].Confidence()) continue;  // a stale entry
    place(v, candidates[v].Best());
  }
  return rotations;
}

}  // namespace

ComponentProblem LargestComponent(const std::vector<RelativeRotation>& edges) {
  ComponentProblem problem;
  std::vector<image_t> all_ids;
  std::vector<int> usable;
  for (size_t e = 0; e < edges.size(); ++e) {
    if (!UsableEdge(edges[e])) {
      ++problem.num_ignored;
      continue;
    }
    usable.push_back(static_cast<int>(e));
    all_ids.push_back(edges[e].node1);
    all_ids.push_back(edges[e].node2);
  }
  std::sort(all_ids.begin(), all_ids.end());
  all_ids.erase(std::unique(all_ids.begin(), all_ids.end()), all_ids.end());
  const auto index_of = [&](image_t id) {
    return static_cast<int>(std::lower_bound(all_ids.begin(), all_ids.end(), id) - all_ids.begin());
  };
  std::vector<std::pair<int, int>> pairs;
  for (int e : usable) pairs.push_back({index_of(edges[e].node1), index_of(edges[e].node2)});
  const GraphComponents components = ConnectedComponents(static_cast<int>(all_ids.size()), pairs);

  std::vector<int> node_index(all_ids.size(), -1);
  for (size_t v = 0; v < all_ids.size(); ++v) {
    if (components.label[v] != 0) continue;
    node_index[v] = static_cast<int>(problem.ids.size());
    problem.ids.push_back(all_ids[v]);
  }
  double max_weight = 0.0;
  for (size_t k = 0; k < usable.size(); ++k) {
    if (components.label[pairs[k].first] != 0) continue;
    const RelativeRotation& edge = edges[usable[k]];
    problem.input_edge.push_back(usable[k]);
    problem.node1.push_back(node_index[pairs[k].first]);
    problem.node2.push_back(node_index[pairs[k].second]);
    problem.measured.push_back(edge.cam2_from_cam1.normalized());
    problem.weight.push_back(edge.weight);
    max_weight = std::max(max_weight, problem.weight.back());
  }
  for (double& w : problem.weight) w /= max_weight;
  if (problem.NumEdges() > 0) problem.root = HeaviestNode(problem);
  return problem;
}

std::vector<Eigen::Quaterniond> TreeRotations(const ComponentProblem& problem,
                                              const RotationAveragingOptions& options) {
  if (options.initialization == RotationInitialization::kMaxWeightTree) {
    return MaxWeightTreeRotations(problem);
  }
  return ConsensusTreeRotations(problem, options.agreement_deg * M_PI / 180.0);
}

}  // namespace rotation_averaging_internal

std::map<image_t, Eigen::Quaterniond> InitialRotations(const std::vector<RelativeRotation>& edges,
                                                       const RotationAveragingOptions& options) {
  options.Check();
  const rotation_averaging_internal::ComponentProblem problem =
      rotation_averaging_internal::LargestComponent(edges);
  std::map<image_t, Eigen::Quaterniond> cam_from_world;
  if (problem.NumEdges() == 0) return cam_from_world;
  const std::vector<Eigen::Quaterniond> rotations =
      rotation_averaging_internal::TreeRotations(problem, options);
  for (int k = 0; k < problem.NumNodes(); ++k) cam_from_world[problem.ids[k]] = rotations[k];
  return cam_from_world;
}

}  // namespace loopsfm
