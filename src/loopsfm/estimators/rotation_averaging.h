#pragma once
// Rotation averaging for the global mapper: the cam_from_world rotation of every image from
// the relative rotations of verified pairs (scene/relative_rotation.h).
//
// With R_k = cam_k_from_world, an edge (1, 2) measures R_12 = R_2 R_1^T. Its residual is the
// rotation vector f = log(R_2^T R_12 R_1), written in world coordinates; its norm is the
// angle between the measured and the estimated relative rotation. With the update
// R_k <- R_k exp(d_k), the linearised residual is d_2 - d_1 - f (Chatterjee and Govindu,
// "Robust relative rotation averaging", 2018), so each iteration solves the weighted graph
// Laplacian of the edges for the three components of the updates, one node held fixed.
//
// Steps, on the largest connected component of the edges only:
//  1. rotations propagated along a spanning tree from the root, the node with the largest
//     total edge weight (ties: the smallest id), which gets the identity and stays fixed.
//     The tree is either the maximum-weight spanning tree (Kruskal), or grown by consensus:
//     each edge from a placed node proposes a rotation for its other node; the next node
//     placed is the one whose best proposal most proposals agree with (the number within
//     agreement_deg, then their total weight), and it gets that proposal. A tree through an
//     outlier edge turns a whole subtree; the consensus tree places a node only once its
//     proposals agree, so outliers that the other edges of a node outvote stay out;
//  2. an L1 stage: per linearisation, the updates minimising sum_e m_e |d_2 - d_1 - f_e|
//     (m: the measurement weights with use_weights, else 1), found by reweighted least
//     squares; where a subtree is turned as a whole, this turns it back in one step when
//     most edges across agree;
//  3. a robust stage: iteratively reweighted least squares with Geman-McClure weights
//     (s^2 / (s^2 + |f|^2))^2, optionally times the measurement weights.
//
//   RotationAveragingResult result = AverageRotations(edges, options);
//   for (const auto& [image_id, cam_from_world] : result.cam_from_world) ...
//   result.report.edge_residual_deg[e]   // per input edge

#include <map>
#include <vector>

#include <Eigen/Geometry>

#include "loopsfm/scene/relative_rotation.h"

namespace loopsfm {

enum class RotationInitialization {
  kMaxWeightTree,  // propagation along the maximum-weight spanning tree
  kConsensusTree,  // the tree grown by consensus (see above)
};

struct RotationAveragingOptions {
  RotationInitialization initialization = RotationInitialization::kConsensusTree;
  // Proposals that the consensus tree counts as agreeing are at most this far apart (degrees).
  double agreement_deg = 10.0;
  // Linearisations of the L1 stage; 0 skips it.
  int num_l1_iterations = 10;
  // Reweighted least-squares steps that solve each linearised L1 problem.
  int num_l1_inner_iterations = 10;
  // Maximum iterations of the robust (Geman-McClure) stage; 0 returns the L1 (or, with no
  // L1 stage either, the spanning-tree) rotations.
  int max_num_iterations = 100;
  // A stage stops when no node's rotation changes by more than this in one iteration (degrees).
  double convergence_threshold_deg = 1e-4;
  // Scale of the Geman-McClure weight (degrees): an edge with this residual gets a quarter of
  // the weight of an exact one; far larger residuals get almost none.
  double robust_scale_deg = 5.0;
  // Multiply the L1 and robust weights by the edges' measurement weights; false: every edge
  // counts the same there. (The trees always use the measurement weights.) Off by default:
  // an outlier pair can have as many inliers as a good one, and weights let a few heavy
  // outliers outvote the good edges of a node.
  bool use_weights = false;
  // Edges whose final residual is above this are counted as outliers in the report (degrees).
  double outlier_threshold_deg = 5.0;
  void Check() const;  // throws InvalidArgument
};

struct RotationAveragingReport {
  // True when the largest component has an edge and every stage's linear solve succeeded.
  bool success = false;
  // True when the last stage run stopped on the convergence threshold.
  bool converged = false;
  int num_input_edges = 0;
  // Input edges not used at all: node1 == node2, or a weight that is not finite and > 0.
  int num_ignored_edges = 0;
  // Nodes and edges of the largest connected component (the ones averaged).
  int num_nodes = 0;
  int num_edges = 0;
  int num_l1_iterations = 0;
  int num_iterations = 0;
  // Largest node update of the last iteration run (degrees).
  double final_update_deg = 0.0;
  // Per input edge, the final angle between measured and estimated relative rotation
  // (degrees); -1 for edges outside the largest component or ignored.
  std::vector<double> edge_residual_deg;
  // Edges of the component whose final residual is above options.outlier_threshold_deg.
  int num_outlier_edges = 0;
  double time_s = 0.0;
};

struct RotationAveragingResult {
  // cam_from_world of every node of the largest component.
  std::map<image_t, Eigen::Quaterniond> cam_from_world;
  RotationAveragingReport report;
};

// The whole method above. Nodes outside the largest component get no rotation. When a linear
// solve fails (report.success false), the rotations are those of the last good iteration.
RotationAveragingResult AverageRotations(const std::vector<RelativeRotation>& edges,
                                         const RotationAveragingOptions& options = {});

// Step 1 alone: the rotations the options' tree propagates over the largest component.
// Edges of equal weight are taken in input order.
std::map<image_t, Eigen::Quaterniond> InitialRotations(
    const std::vector<RelativeRotation>& edges, const RotationAveragingOptions& options = {});

// Angle between an edge's measured rotation and the one the two rotations give (degrees).
double RotationResidualDegrees(const RelativeRotation& edge,
                               const Eigen::Quaterniond& cam1_from_world,
                               const Eigen::Quaterniond& cam2_from_world);

}  // namespace loopsfm
