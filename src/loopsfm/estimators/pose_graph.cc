#include "loopsfm/estimators/pose_graph.h"

#include <algorithm>
#include <cmath>
#include <thread>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// The residual of one edge (see pose_graph.h). Parameter blocks per node: quaternion
// (Eigen x, y, z, w), centre (3), log scale (1).
class Sim3EdgeCost {
 public:
  Sim3EdgeCost(const PoseGraphEdge& edge, double unit) : edge_(edge), unit_(unit) {}

  static ceres::CostFunction* Create(const PoseGraphEdge& edge, double unit) {
    return new ceres::AutoDiffCostFunction<Sim3EdgeCost, 7, 4, 3, 1, 4, 3, 1>(
        new Sim3EdgeCost(edge, unit));
  }

  template <typename T>
  bool operator()(const T* q_i, const T* c_i, const T* log_s_i, const T* q_j, const T* c_j,
                  const T* log_s_j, T* residuals) const {
    using Quaternion = Eigen::Quaternion<T>;
    using Vector3 = Eigen::Matrix<T, 3, 1>;
    const Eigen::Map<const Quaternion> rotation_i(q_i), rotation_j(q_j);
    const Eigen::Map<const Vector3> centre_i(c_i), centre_j(c_j);
    const Quaternion measured_rotation = edge_.measured.rotation.cast<T>();
    const Quaternion error = measured_rotation.conjugate() * rotation_i.conjugate() * rotation_j;
    // 2 * vec(q) with the sign chosen so w >= 0 (the same rotation either way).
    const T sign = error.w() < T(0) ? T(-1) : T(1);
    const Vector3 translation =
        (rotation_i.conjugate() * (centre_j - centre_i)) * ceres::exp(-log_s_i[0]);
    const Vector3 translation_error =
        (translation - edge_.measured.translation.cast<T>()) / T(unit_);
    for (int k = 0; k < 3; ++k) {
      residuals[k] = T(2.0 * edge_.rotation_weight) * sign * error.vec()[k];
      residuals[3 + k] = T(edge_.translation_weight) * translation_error[k];
    }
    residuals[6] = T(edge_.scale_weight) *
                   (log_s_j[0] - log_s_i[0] - T(std::log(edge_.measured.scale)));
    return true;
  }

 private:
  PoseGraphEdge edge_;
  double unit_;
};

struct NodeBlocks {
  double rotation[4];
  double centre[3];
  double log_scale[1];
};

}  // namespace

void PoseGraphOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(max_num_iterations > 0, "max_num_iterations must be > 0, got {}",
                         max_num_iterations);
}

void PoseGraph::AddNode(image_t id, const Sim3d& world_from_cam) {
  LOOPSFM_CHECK(world_from_cam.scale > 0.0);
  nodes_[id] = world_from_cam;
}

const Sim3d& PoseGraph::Node(image_t id) const { return nodes_.at(id); }

void PoseGraph::AddEdge(const PoseGraphEdge& edge) {
  LOOPSFM_CHECK(HasNode(edge.node1) && HasNode(edge.node2) && edge.node1 != edge.node2);
  LOOPSFM_CHECK(edge.measured.scale > 0.0);
  edges_.push_back(edge);
}

Sim3d PoseGraph::RelativeFromNodes(image_t i, image_t j) const {
  return Node(i).Inverse() * Node(j);
}

void PoseGraph::SetConstant(image_t id) {
  LOOPSFM_CHECK(HasNode(id));
  constant_.push_back(id);
}

bool PoseGraph::Optimize(const PoseGraphOptions& options) {
  options.Check();
  LOOPSFM_CHECK(!constant_.empty());
  Timer timer;
  report_ = {};
  report_.num_nodes = static_cast<int>(nodes_.size());
  report_.num_edges = static_cast<int>(edges_.size());

  double unit = options.translation_unit;
  if (unit <= 0.0) {
    std::vector<double> lengths;
    for (const PoseGraphEdge& edge : edges_) lengths.push_back(edge.measured.translation.norm());
    if (!lengths.empty()) {
      std::nth_element(lengths.begin(), lengths.begin() + lengths.size() / 2, lengths.end());
      unit = lengths[lengths.size() / 2];
    }
    if (!(unit > 0.0)) unit = 1.0;
  }

  std::map<image_t, NodeBlocks> blocks;
  for (const auto& [id, node] : nodes_) {
    NodeBlocks& b = blocks[id];
    const Eigen::Quaterniond q = node.rotation.normalized();
    b.rotation[0] = q.x();
    b.rotation[1] = q.y();
    b.rotation[2] = q.z();
    b.rotation[3] = q.w();
    for (int k = 0; k < 3; ++k) b.centre[k] = node.translation[k];
    b.log_scale[0] = std::log(node.scale);
  }

  ceres::Problem problem;
  for (const PoseGraphEdge& edge : edges_) {
    NodeBlocks& a = blocks.at(edge.node1);
    NodeBlocks& b = blocks.at(edge.node2);
    problem.AddResidualBlock(Sim3EdgeCost::Create(edge, unit), nullptr, a.rotation, a.centre,
                             a.log_scale, b.rotation, b.centre, b.log_scale);
  }
  for (auto& [id, b] : blocks) {
    if (!problem.HasParameterBlock(b.rotation)) continue;
    problem.SetManifold(b.rotation, new ceres::EigenQuaternionManifold);
  }
  for (image_t id : constant_) {
    NodeBlocks& b = blocks.at(id);
    if (!problem.HasParameterBlock(b.rotation)) continue;
    problem.SetParameterBlockConstant(b.rotation);
    problem.SetParameterBlockConstant(b.centre);
    problem.SetParameterBlockConstant(b.log_scale);
  }

  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  solver_options.max_num_iterations = options.max_num_iterations;
  solver_options.num_threads = options.num_threads > 0
                                   ? options.num_threads
                                   : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  solver_options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);

  report_.num_iterations = static_cast<int>(summary.iterations.size());
  report_.initial_cost = summary.initial_cost;
  report_.final_cost = summary.final_cost;
  report_.termination = ceres::TerminationTypeToString(summary.termination_type);
  report_.success = summary.IsSolutionUsable();
  report_.time_s = timer.ElapsedSeconds();
  if (!report_.success) return false;
  for (auto& [id, node] : nodes_) {
    const NodeBlocks& b = blocks.at(id);
    node.rotation =
        Eigen::Quaterniond(b.rotation[3], b.rotation[0], b.rotation[1], b.rotation[2]).normalized();
    node.translation = Eigen::Vector3d(b.centre[0], b.centre[1], b.centre[2]);
    node.scale = std::exp(b.log_scale[0]);
  }
  return true;
}

}  // namespace loopsfm
