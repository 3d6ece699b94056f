#include "loopsfm/estimators/pose_graph.h"

#include <gtest/gtest.h>

#include <cmath>

#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// A closed ring of n cameras of radius 10 looking outwards, as world_from_cam.
std::vector<Sim3d> Ring(int n) {
  std::vector<Sim3d> poses;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * M_PI * i / n;
    Sim3d pose;
    pose.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()) *
                                       Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()));
    pose.translation = Eigen::Vector3d(10 * std::cos(a), 10 * std::sin(a), 0.0);
    poses.push_back(pose);
  }
  return poses;
}

double MaxCentreError(const PoseGraph& graph, const std::vector<Sim3d>& truth) {
  double worst = 0.0;
  for (size_t i = 0; i < truth.size(); ++i) {
    worst = std::max(worst, (graph.Node(i).translation - truth[i].translation).norm());
  }
  return worst;
}

// Odometry with a small rotation and scale drift per step, as a monocular mapper makes it.
std::vector<Sim3d> Drifted(const std::vector<Sim3d>& truth, double yaw_per_step,
                           double scale_per_step) {
  std::vector<Sim3d> drifted = {truth[0]};
  Sim3d step_error;
  step_error.rotation = Eigen::AngleAxisd(yaw_per_step, Eigen::Vector3d::UnitY());
  step_error.scale = 1.0;
  for (size_t i = 1; i < truth.size(); ++i) {
    Sim3d relative = truth[i - 1].Inverse() * truth[i];
    relative = step_error * relative;
    relative.translation *= std::pow(scale_per_step, static_cast<double>(i));
    Sim3d next = drifted.back() * relative;
    next.scale = 1.0;  // a drifted model has no scale of its own per camera
    drifted.push_back(next);
  }
  return drifted;
}

TEST(PoseGraph, ComposeAndInverseAreConsistent) {
  Random random(3);
  Sim3d a, b;
  a.scale = 1.7;
  a.rotation = Eigen::Quaterniond(random.Normal(), random.Normal(), random.Normal(), random.Normal()).normalized();
  a.translation = Eigen::Vector3d(1, -2, 3);
  b.scale = 0.4;
  b.rotation = Eigen::Quaterniond(random.Normal(), random.Normal(), random.Normal(), random.Normal()).normalized();
  b.translation = Eigen::Vector3d(-0.5, 4, 2);
  const Eigen::Vector3d x(0.3, 0.2, -1.1);
  EXPECT_LT(((a * b) * x - a * (b * x)).norm(), 1e-12);
  EXPECT_LT(((a.Inverse() * a) * x - x).norm(), 1e-12);
}

TEST(PoseGraph, ConsistentMeasurementsAreAFixedPoint) {
  const auto truth = Ring(30);
  PoseGraph graph;
  for (size_t i = 0; i < truth.size(); ++i) graph.AddNode(i, truth[i]);
  for (size_t i = 0; i < truth.size(); ++i) {
    const image_t j = (i + 1) % truth.size();
    graph.AddEdge({.node1 = static_cast<image_t>(i), .node2 = j,
                   .measured = graph.RelativeFromNodes(i, j)});
  }
  graph.SetConstant(0);
  ASSERT_TRUE(graph.Optimize());
  EXPECT_LT(graph.report().final_cost, 1e-20);
  EXPECT_LT(MaxCentreError(graph, truth), 1e-9);
}

TEST(PoseGraph, LoopEdgeSpreadsRotationAndScaleDrift) {
  const int n = 60;
  const auto truth = Ring(n);
  const auto drifted = Drifted(truth, 0.004, 0.995);
  PoseGraph graph;
  for (int i = 0; i < n; ++i) graph.AddNode(i, drifted[i]);
  // Odometry as the drifted model says, and one loop edge from the truth (what a loop
  // detection measures between the last and the first camera).
  for (int i = 0; i + 1 < n; ++i) {
    graph.AddEdge({.node1 = static_cast<image_t>(i), .node2 = static_cast<image_t>(i + 1),
                   .measured = graph.RelativeFromNodes(i, i + 1)});
  }
  const double before = MaxCentreError(graph, truth);
  // Near the last camera the drifted model is scaled by sigma against the truth: a point at
  // x in that camera's frame is at x / sigma in the true one, so the measured transform
  // carries a scale of 1 / sigma.
  const double sigma = std::pow(0.995, n - 1);
  Sim3d unscale;
  unscale.scale = 1.0 / sigma;
  graph.AddEdge({.node1 = 0, .node2 = static_cast<image_t>(n - 1),
                 .measured = truth[0].Inverse() * truth[n - 1] * unscale,
                 .rotation_weight = 10.0, .translation_weight = 10.0, .scale_weight = 10.0});
  graph.SetConstant(0);
  ASSERT_TRUE(graph.Optimize()) << graph.report().termination;
  const double after = MaxCentreError(graph, truth);
  // The drift (a few metres at the end of the ring) mostly goes.
  EXPECT_GT(before, 1.0);
  EXPECT_LT(after, 0.2 * before);
  // The end of the ring meets its start again.
  const Eigen::Vector3d gap_before = drifted[n - 1].translation - drifted[0].translation;
  const Eigen::Vector3d gap_truth = truth[n - 1].translation - truth[0].translation;
  const Eigen::Vector3d gap_after = graph.Node(n - 1).translation - graph.Node(0).translation;
  EXPECT_LT((gap_after - gap_truth).norm(), 0.1 * (gap_before - gap_truth).norm());
  // Scale drift shows as node scales above 1 towards the end (the drifted model shrank).
  EXPECT_NEAR(graph.Node(n - 1).scale, 1.0 / sigma, 0.05);
}

TEST(PoseGraph, BadInputIsRejected) {
  PoseGraph graph;
  graph.AddNode(1, Sim3d());
  EXPECT_DEATH(graph.AddEdge({.node1 = 1, .node2 = 2}), "");
  PoseGraphOptions options;
  options.max_num_iterations = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
