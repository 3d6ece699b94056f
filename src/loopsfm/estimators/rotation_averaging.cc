#include "loopsfm/estimators/rotation_averaging.h"

#include <algorithm>
#include <cmath>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include "loopsfm/estimators/rotation_averaging_internal.h"
#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

using rotation_averaging_internal::ComponentProblem;

constexpr double kRadToDeg = 180.0 / M_PI;
// Smallest Geman-McClure weight: keeps the system well conditioned when every edge of a node
// looks like an outlier.
constexpr double kMinRobustWeight = 1e-8;
// Residual (radians) below which the L1 weight 1 / |r| stops growing.
constexpr double kL1MinResidual = 1e-4;

// The rotation vector log(R_2^T R_12 R_1).
Eigen::Vector3d ResidualVector(const Eigen::Quaterniond& cam2_from_cam1,
                               const Eigen::Quaterniond& cam1_from_world,
                               const Eigen::Quaterniond& cam2_from_world) {
  const Eigen::AngleAxisd error(
      (cam2_from_world.conjugate() * cam2_from_cam1 * cam1_from_world).normalized());
  return error.angle() * error.axis();
}

// Solves min sum_e w_e |d_2 - d_1 - f_e|^2 over the node updates d with the root's held at
// zero: the weighted graph Laplacian without the root's row and column, the same for the
// three components. The sparsity pattern is analysed once, the values factorised per call.
class LaplacianSolver {
 public:
  explicit LaplacianSolver(const ComponentProblem& problem) : problem_(problem) {
    int next = 0;
    row_.assign(problem.NumNodes(), -1);
    for (int k = 0; k < problem.NumNodes(); ++k) {
      if (k != problem.root) row_[k] = next++;
    }
    num_rows_ = next;
  }

  // Fills `updates` (one row per node); false when the factorisation fails.
  bool Solve(const std::vector<double>& weights, const std::vector<Eigen::Vector3d>& residuals,
             Eigen::MatrixX3d* updates) {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(4 * problem_.NumEdges());
    Eigen::MatrixX3d rhs = Eigen::MatrixX3d::Zero(num_rows_, 3);
    for (int e = 0; e < problem_.NumEdges(); ++e) {
      const int r1 = row_[problem_.node1[e]];
      const int r2 = row_[problem_.node2[e]];
      const double w = weights[e];
      if (r1 >= 0) {
        triplets.emplace_back(r1, r1, w);
        rhs.row(r1) -= w * residuals[e].transpose();
      }
      if (r2 >= 0) {
        triplets.emplace_back(r2, r2, w);
        rhs.row(r2) += w * residuals[e].transpose();
      }
      if (r1 >= 0 && r2 >= 0) {
        triplets.emplace_back(r1, r2, -w);
        triplets.emplace_back(r2, r1, -w);
      }
    }
    Eigen::SparseMatrix<double> matrix(num_rows_, num_rows_);
    matrix.setFromTriplets(triplets.begin(), triplets.end());
    if (!analysed_) {
      ldlt_.analyzePattern(matrix);
      analysed_ = true;
    }
    ldlt_.factorize(matrix);
    if (ldlt_.info() != Eigen::Success) return false;
    const Eigen::MatrixX3d solution = ldlt_.solve(rhs);
    if (ldlt_.info() != Eigen::Success || !solution.allFinite()) return false;
    updates->setZero(problem_.NumNodes(), 3);
    for (int k = 0; k < problem_.NumNodes(); ++k) {
      if (row_[k] >= 0) updates->row(k) = solution.row(row_[k]);
    }
    return true;
  }

 private:
  const ComponentProblem& problem_;
  std::vector<int> row_;
  int num_rows_ = 0;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt_;
  bool analysed_ = false;
};

enum class Stage { kL1, kRobust };

struct StageResult {
  int num_iterations = 0;
  bool converged = false;
  bool solved = true;
  double last_update_deg = 0.0;
};

// The linearised L1 problem min_d sum_e m_e |d_2 - d_1 - f_e| (m: `edge_weights`, the root's
// d fixed at zero), solved approximately by reweighted least squares from d = 0.
bool SolveL1(const ComponentProblem& problem, const std::vector<double>& edge_weights,
             const std::vector<Eigen::Vector3d>& residuals, int num_inner_iterations,
             LaplacianSolver& solver, Eigen::MatrixX3d* updates) {
  std::vector<double> weights(problem.NumEdges());
  updates->setZero(problem.NumNodes(), 3);
  for (int it = 0; it < num_inner_iterations; ++it) {
    for (int e = 0; e < problem.NumEdges(); ++e) {
      const Eigen::Vector3d r =
          (updates->row(problem.node2[e]) - updates->row(problem.node1[e])).transpose() -
          residuals[e];
      weights[e] = edge_weights[e] / std::max(r.norm(), kL1MinResidual);
    }
    if (!solver.Solve(weights, residuals, updates)) return false;
  }
  return true;
}

// One reweighted least-squares step with Geman-McClure weights at the current residuals,
// times `edge_weights`.
bool SolveRobust(const ComponentProblem& problem, const std::vector<double>& edge_weights,
                 const std::vector<Eigen::Vector3d>& residuals, double scale_rad,
                 LaplacianSolver& solver, Eigen::MatrixX3d* updates) {
  std::vector<double> weights(problem.NumEdges());
  for (int e = 0; e < problem.NumEdges(); ++e) {
    const double r = residuals[e].norm();
    const double g = scale_rad * scale_rad / (scale_rad * scale_rad + r * r);
    weights[e] = edge_weights[e] * std::max(g * g, kMinRobustWeight);
  }
  return solver.Solve(weights, residuals, updates);
}

// R_k <- R_k exp(d_k); returns the largest |d_k| (radians).
double ApplyUpdates(const Eigen::MatrixX3d& updates, std::vector<Eigen::Quaterniond>* rotations) {
  double max_update = 0.0;
  for (int k = 0; k < static_cast<int>(rotations->size()); ++k) {
    const Eigen::Vector3d d = updates.row(k).transpose();
    const double angle = d.norm();
    if (angle == 0.0) continue;
    Eigen::Quaterniond& rotation = (*rotations)[k];
    rotation = (rotation * Eigen::Quaterniond(Eigen::AngleAxisd(angle, d / angle))).normalized();
    max_update = std::max(max_update, angle);
  }
  return max_update;
}

// One stage: linearise every edge at the current rotations, solve for the updates (the L1
// problem, or one robust reweighted step), apply them; until converged or out of iterations.
StageResult RunStage(const ComponentProblem& problem, Stage stage, int max_num_iterations,
                     const RotationAveragingOptions& options, LaplacianSolver& solver,
                     std::vector<Eigen::Quaterniond>* rotations) {
  const std::vector<double> edge_weights =
      options.use_weights ? problem.weight : std::vector<double>(problem.NumEdges(), 1.0);
  std::vector<Eigen::Vector3d> residuals(problem.NumEdges());
  Eigen::MatrixX3d updates;
  StageResult result;
  while (result.num_iterations < max_num_iterations) {
    for (int e = 0; e < problem.NumEdges(); ++e) {
      residuals[e] = ResidualVector(problem.measured[e], (*rotations)[problem.node1[e]],
                                    (*rotations)[problem.node2[e]]);
    }
    const bool solved = stage == Stage::kL1
                            ? SolveL1(problem, edge_weights, residuals,
                                      options.num_l1_inner_iterations, solver, &updates)
                            : SolveRobust(problem, edge_weights, residuals,
                                          options.robust_scale_deg / kRadToDeg, solver, &updates);
    if (!solved) {
      result.solved = false;
      break;
    }
    ++result.num_iterations;
    result.last_update_deg = ApplyUpdates(updates, rotations) * kRadToDeg;
    if (result.last_update_deg < options.convergence_threshold_deg) {
      result.converged = true;
      break;
    }
  }
  return result;
}

}  // namespace

void RotationAveragingOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(std::isfinite(agreement_deg) && agreement_deg > 0.0,
                         "agreement_deg must be a positive number of degrees, got {}",
                         agreement_deg);
  LOOPSFM_REQUIRE_OPTION(num_l1_iterations >= 0, "num_l1_iterations must be >= 0, got {}",
                         num_l1_iterations);
  LOOPSFM_REQUIRE_OPTION(num_l1_inner_iterations > 0, "num_l1_inner_iterations must be > 0, got {}",
                         num_l1_inner_iterations);
  LOOPSFM_REQUIRE_OPTION(max_num_iterations >= 0, "max_num_iterations must be >= 0, got {}",
                         max_num_iterations);
  LOOPSFM_REQUIRE_OPTION(
      std::isfinite(convergence_threshold_deg) && convergence_threshold_deg > 0.0,
      "convergence_threshold_deg must be a positive number of degrees, got {}",
      convergence_threshold_deg);
  LOOPSFM_REQUIRE_OPTION(std::isfinite(robust_scale_deg) && robust_scale_deg > 0.0,
                         "robust_scale_deg must be a positive number of degrees, got {}",
                         robust_scale_deg);
  LOOPSFM_REQUIRE_OPTION(std::isfinite(outlier_threshold_deg) && outlier_threshold_deg > 0.0,
                         "outlier_threshold_deg must be a positive number of degrees, got {}",
                         outlier_threshold_deg);
}

double RotationResidualDegrees(const RelativeRotation& edge,
                               const Eigen::Quaterniond& cam1_from_world,
                               const Eigen::Quaterniond& cam2_from_world) {
  return RotationAngleDegrees(cam2_from_world.conjugate() * edge.cam2_from_cam1.normalized() *
                              cam1_from_world);
}

RotationAveragingResult AverageRotations(const std::vector<RelativeRotation>& edges,
                                         const RotationAveragingOptions& options) {
  options.Check();
  const Timer timer;
  RotationAveragingResult result;
  RotationAveragingReport& report = result.report;
  report.num_input_edges = static_cast<int>(edges.size());
  report.edge_residual_deg.assign(edges.size(), -1.0);
  const ComponentProblem problem = rotation_averaging_internal::LargestComponent(edges);
  report.num_ignored_edges = problem.num_ignored;
  report.num_nodes = problem.NumNodes();
  report.num_edges = problem.NumEdges();
  if (problem.NumEdges() == 0) {
    report.time_s = timer.ElapsedSeconds();
    return result;
  }

  std::vector<Eigen::Quaterniond> rotations =
      rotation_averaging_internal::TreeRotations(problem, options);
  LaplacianSolver solver(problem);
  bool solved = true;
  if (options.num_l1_iterations > 0) {
    const StageResult l1 =
        RunStage(problem, Stage::kL1, options.num_l1_iterations, options, solver, &rotations);
    report.num_l1_iterations = l1.num_iterations;
    report.converged = l1.converged;
    report.final_update_deg = l1.last_update_deg;
    solved = l1.solved;
  }
  if (solved && options.max_num_iterations > 0) {
    const StageResult robust =
        RunStage(problem, Stage::kRobust, options.max_num_iterations, options, solver, &rotations);
    report.num_iterations = robust.num_iterations;
    report.converged = robust.converged;
    report.final_update_deg = robust.last_update_deg;
    solved = robust.solved;
  }
  report.success = solved;

  for (int e = 0; e < problem.NumEdges(); ++e) {
    const int input = problem.input_edge[e];
    const double residual = RotationResidualDegrees(edges[input], rotations[problem.node1[e]],
                                                    rotations[problem.node2[e]]);
    report.edge_residual_deg[input] = residual;
    if (residual > options.outlier_threshold_deg) ++report.num_outlier_edges;
  }
  for (int k = 0; k < problem.NumNodes(); ++k) result.cam_from_world[problem.ids[k]] = rotations[k];
  report.time_s = timer.ElapsedSeconds();
  return result;
}

}  // namespace loopsfm
