#include "loopsfm/robust/p3p.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

Eigen::Quaterniond RandomRotation(Random& random) {
  return Eigen::Quaterniond(random.Normal(), random.Normal(), random.Normal(), random.Normal())
      .normalized();
}

struct Problem {
  Rigid3d cam_from_world;
  std::array<Eigen::Vector3d, 3> bearings;
  std::array<Eigen::Vector3d, 3> points3D;
};

// Points at depths in [min_depth, max_depth] whose rays lie within half_fov of the
// optical axis (half_fov >= pi: anywhere on the sphere), seen from a random pose.
Problem RandomProblem(Random& random, double half_fov = 0.6, double min_depth = 1.0,
                      double max_depth = 10.0) {
  Problem problem;
  problem.cam_from_world =
      Rigid3d(RandomRotation(random),
              Eigen::Vector3d(random.Normal(0, 3), random.Normal(0, 3), random.Normal(0, 3)));
  const Rigid3d world_from_cam = problem.cam_from_world.Inverse();
  for (int i = 0; i < 3; ++i) {
    const double theta = std::acos(random.UniformReal(std::cos(std::min(half_fov, M_PI)), 1.0));
    const double phi = random.UniformReal(0, 2 * M_PI);
    const Eigen::Vector3d ray(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                              std::cos(theta));
    problem.bearings[i] = ray;
    problem.points3D[i] = world_from_cam * (random.UniformReal(min_depth, max_depth) * ray);
  }
  return problem;
}

double RotationError(const Rigid3d& a, const Rigid3d& b) {
  return a.rotation.angularDistance(b.rotation);
}

// Largest angle between an input bearing and the ray to its point under a solution.
double MaxBearingError(const Problem& problem, const Rigid3d& cam_from_world) {
  double max_error = 0.0;
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d p = cam_from_world * problem.points3D[i];
    const Eigen::Vector3d y = problem.bearings[i].normalized();
    max_error = std::max(max_error, std::atan2(y.cross(p).norm(), y.dot(p)));
  }
  return max_error;
}

bool IsFinite(const Rigid3d& pose) {
  return pose.rotation.coeffs().allFinite() && pose.translation.allFinite();
}

// Runs num_trials problems and returns the fraction where a solution is within tol of the
// truth; every returned solution must be finite and consistent with the input.
double SuccessRate(Random& random, int num_trials, double half_fov, double tolerance,
                   double min_depth = 1.0, double max_depth = 10.0) {
  int num_found = 0;
  for (int trial = 0; trial < num_trials; ++trial) {
    const Problem problem = RandomProblem(random, half_fov, min_depth, max_depth);
    const std::vector<Rigid3d> solutions = SolveP3P(problem.bearings, problem.points3D);
    EXPECT_LE(solutions.size(), 4u);
    bool found = false;
    for (const Rigid3d& solution : solutions) {
      EXPECT_TRUE(IsFinite(solution));
      EXPECT_LT(MaxBearingError(problem, solution), 1e-6);
      const double translation_error =
          (solution.translation - problem.cam_from_world.translation).norm();
      if (RotationError(solution, problem.cam_from_world) < tolerance &&
          translation_error < tolerance * (1.0 + problem.cam_from_world.translation.norm())) {
        found = true;
      }
    }
    num_found += found ? 1 : 0;
  }
  return static_cast<double>(num_found) / num_trials;
}

TEST(P3P, FindsTheTruePoseInRandomProblems) {
  Random random(101);
  const double rate = SuccessRate(random, 1000, 0.6, 1e-6);
  RecordProperty("success_rate", std::to_string(rate));
  EXPECT_GT(rate, 0.99);
}

TEST(P3P, FindsTheTruePoseForBearingsAllAroundTheCamera) {
  Random random(102);
  EXPECT_GT(SuccessRate(random, 1000, M_PI, 1e-6), 0.99);
}

TEST(P3P, FindsTheTruePoseForNarrowFieldOfViewAndFarPoints) {
  Random random(103);
  // 5 degrees field of view, points 50..60 units away: a weak but regular geometry.
  EXPECT_GT(SuccessRate(random, 1000, 0.044, 1e-6, 50.0, 60.0), 0.97);
}

TEST(P3P, ReturnsNothingForDegenerateInput) {
  Random random(104);
  Problem problem = RandomProblem(random);
  // Collinear world points.
  problem.points3D[2] = 0.3 * problem.points3D[0] + 0.7 * problem.points3D[1];
  EXPECT_TRUE(SolveP3P(problem.bearings, problem.points3D).empty());
  // Coincident bearings.
  problem = RandomProblem(random);
  problem.bearings[1] = problem.bearings[0];
  EXPECT_TRUE(SolveP3P(problem.bearings, problem.points3D).empty());
  // Zero and non-finite input.
  problem = RandomProblem(random);
  problem.bearings[2].setZero();
  EXPECT_TRUE(SolveP3P(problem.bearings, problem.points3D).empty());
  problem = RandomProblem(random);
  problem.points3D[1].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(SolveP3P(problem.bearings, problem.points3D).empty());
}

// Configurations close to the degenerate ones must not produce NaN or invalid poses.
// Nearly collinear world points are inherently ill-conditioned for a solver working on
// depths (the rotation about the line depends on 1/eps^2-amplified depth errors, and
// nearby solutions merge), so there only finiteness and consistency are required.
TEST(P3P, NearDegenerateConfigurationsGiveFiniteConsistentPoses) {
  Random random(105);
  int num_found = 0, num_trials = 0;
  for (int trial = 0; trial < 300; ++trial) {
    for (int kind = 0; kind < 3; ++kind) {
      Problem problem = RandomProblem(random);
      const Rigid3d world_from_cam = problem.cam_from_world.Inverse();
      const double eps = std::pow(10.0, -random.UniformReal(3, 9));
      if (kind == 0) {
        // Nearly collinear world points.
        const Eigen::Vector3d on_line = 0.4 * problem.points3D[0] + 0.6 * problem.points3D[1];
        problem.points3D[2] = on_line + eps * Eigen::Vector3d(random.Normal(), random.Normal(),
                                                              random.Normal());
      } else if (kind == 1) {
        // Camera centre nearly in the plane of the points: three nearly coplanar rays.
        problem.bearings[2] =
            (0.5 * problem.bearings[0] + 0.5 * problem.bearings[1]).normalized() +
            eps * Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal());
        problem.bearings[2].normalize();
        problem.points3D[2] = world_from_cam * (random.UniformReal(1, 10) * problem.bearings[2]);
      } else {
        // Camera on the cylinder through the points, perpendicular to their plane (the
        // "danger cylinder", where solutions merge): points on a unit circle around the
        // camera's optical axis would put it on the axis, so place the circle beside it.
        const double height = random.UniformReal(2, 6);
        for (int i = 0; i < 3; ++i) {
          const double angle = random.UniformReal(0.3, 2.8) + 2.0 * i;
          const Eigen::Vector3d in_cam(1.0 + std::cos(angle), std::sin(angle), height);
          problem.bearings[i] = in_cam.normalized();
          problem.points3D[i] = world_from_cam * in_cam;
        }
      }
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d in_cam = problem.cam_from_world * problem.points3D[i];
        if (kind != 1 || i != 2) problem.bearings[i] = in_cam.normalized();
      }
      const std::vector<Rigid3d> solutions = SolveP3P(problem.bearings, problem.points3D);
      num_trials += kind == 0 ? 0 : 1;
      // Consistency tolerance from the conditioning: well-conditioned kinds reproduce their
      // bearings to ~1e-11 (1e-6 leaves a wide margin); for nearly collinear points the
      // depths, and so the bearings, carry rounding errors amplified by the inverse of the
      // third point's relative distance from the line (measured on an AVX-512 machine:
      // error * eps_rel up to 280 units of roundoff), so allow 1e5 units.
      double tolerance = 1e-6;
      if (kind == 0) {
        const Eigen::Vector3d line = problem.points3D[1] - problem.points3D[0];
        const double eps_rel =
            line.cross(problem.points3D[2] - problem.points3D[0]).norm() / line.squaredNorm();
        tolerance = std::max(1e-6, 1e5 * std::numeric_limits<double>::epsilon() / eps_rel);
      }
      bool found = false;
      for (const Rigid3d& solution : solutions) {
        ASSERT_TRUE(IsFinite(solution));
        EXPECT_LT(MaxBearingError(problem, solution), tolerance) << "kind " << kind;
        found |= RotationError(solution, problem.cam_from_world) < 1e-3;
      }
      num_found += found && kind != 0 ? 1 : 0;
    }
  }
  // Ill-conditioned, so only a loose accuracy is asked, but the truth is mostly found.
  EXPECT_GT(static_cast<double>(num_found) / num_trials, 0.95);
}

TEST(Cubic, SolvesKnownPolynomials) {
  double roots[3];
  // (x - 1)(x + 2)(x - 3) = x^3 - 2x^2 - 5x + 6.
  ASSERT_EQ(internal::SolveCubicReal(1, -2, -5, 6, roots), 3);
  std::sort(roots, roots + 3);
  EXPECT_NEAR(roots[0], -2, 1e-14);
  EXPECT_NEAR(roots[1], 1, 1e-14);
  EXPECT_NEAR(roots[2], 3, 1e-14);
  // (x - 2)(x^2 + 1): one real root; scaled by -4.
  ASSERT_EQ(internal::SolveCubicReal(-4, 8, -4, 8, roots), 1);
  EXPECT_NEAR(roots[0], 2, 1e-14);
  // Leading coefficient zero: 2x^2 - 2 = 0.
  ASSERT_EQ(internal::SolveCubicReal(0, 2, 0, -2, roots), 2);
  std::sort(roots, roots + 2);
  EXPECT_NEAR(roots[0], -1, 1e-15);
  EXPECT_NEAR(roots[1], 1, 1e-15);
  // Triple root.
  ASSERT_GE(internal::SolveCubicReal(1, -3, 3, -1, roots), 1);
  EXPECT_NEAR(roots[0], 1, 1e-5);
  // Widely spread roots 1e-4, 1, 1e4: (x - a)(x - b)(x - c).
  const double a = 1e-4, b = 1.0, c = 1e4;
  ASSERT_EQ(internal::SolveCubicReal(1, -(a + b + c), a * b + a * c + b * c, -a * b * c, roots),
            3);
  std::sort(roots, roots + 3);
  EXPECT_NEAR(roots[0], a, 1e-12 * a);
  EXPECT_NEAR(roots[1], b, 1e-12 * b);
  EXPECT_NEAR(roots[2], c, 1e-12 * c);
}

}  // namespace
}  // namespace loopsfm
