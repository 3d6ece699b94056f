#pragma once
// Pose graph optimisation over similarity transforms (7 degrees of freedom per node), for
// loop closing: monocular drift bends the path and changes its scale, so every camera gets
// a rotation, a centre and a scale.
//
// Node i is world_from_cam_i as a similarity: x_world = s_i * R_i * x_cam + c_i, where c_i
// is the camera centre and s_i the scale of the camera's local frame (1 for every camera of
// a drifted model; loop closing changes it where the scale drifted). An edge (i, j) holds
// a measured cam_i_from_cam_j = T_i^-1 * T_j. Its residual, with T_ij the measurement and
// the estimate's relative transform written (s, R, t):
//   rotation     2 * vec(q_ij^-1 * q_i^-1 * q_j)                          (3, radians)
//   translation  (R_i^T (c_j - c_i) / s_i - t_ij) / length                 (3)
//   scale        log(s_j / s_i) - log(s_ij)                                (1)
// each weighted by the edge's weights; `length` is the options' translation unit, so a
// translation error of one unit costs as much as a radian.
//
//   PoseGraph graph;
//   graph.AddNode(id, world_from_cam);           // as in the drifted model
//   graph.AddEdge({i, j, graph.RelativeFromNodes(i, j)});  // consecutive / co-visible
//   graph.AddEdge(old, recent, loop_measurement, loop_weight);
//   graph.SetConstant(first);
//   graph.Optimize(options);                     // nodes hold the corrected poses
#include <map>
#include <string>
#include <vector>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/camera.h"

namespace loopsfm {

struct PoseGraphOptions {
  // Length of one translation unit in the residual (world units); <= 0: the median length
  // of the edges' measured translations.
  double translation_unit = 0.0;
  int max_num_iterations = 100;
  // Threads for Ceres; <= 0: all hardware threads.
  int num_threads = -1;
  void Check() const;  // throws InvalidArgument
};

struct PoseGraphEdge {
  image_t node1 = kInvalidImageId;
  image_t node2 = kInvalidImageId;
  // cam1_from_cam2 as a similarity.
  Sim3d measured;
  double rotation_weight = 1.0;
  double translation_weight = 1.0;
  double scale_weight = 1.0;
};

struct PoseGraphReport {
  bool success = false;
  int num_nodes = 0;
  int num_edges = 0;
  int num_iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double time_s = 0.0;
  std::string termination;
};

class PoseGraph {
 public:
  // A node's pose: world_from_cam with the scale of the camera's local frame.
  void AddNode(image_t id, const Sim3d& world_from_cam);
  bool HasNode(image_t id) const { return nodes_.count(id) > 0; }
  const Sim3d& Node(image_t id) const;
  const std::map<image_t, Sim3d>& Nodes() const { return nodes_; }
  // Both nodes must exist.
  void AddEdge(const PoseGraphEdge& edge);
  const std::vector<PoseGraphEdge>& Edges() const { return edges_; }
  // The edge measurement the current node poses give: T_i^-1 * T_j.
  Sim3d RelativeFromNodes(image_t i, image_t j) const;
  // Holds a node fixed (at least one must be, for the gauge).
  void SetConstant(image_t id);
  // Minimises the weighted residuals (Levenberg-Marquardt, sparse normal Cholesky) and
  // writes the result into the nodes. Returns report().success; on failure the nodes keep
  // their previous poses.
  bool Optimize(const PoseGraphOptions& options = {});
  const PoseGraphReport& report() const { return report_; }

 private:
  std::map<image_t, Sim3d> nodes_;
  std::vector<PoseGraphEdge> edges_;
  std::vector<image_t> constant_;
  PoseGraphReport report_;
};

}  // namespace loopsfm
