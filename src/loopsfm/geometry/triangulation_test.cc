#include "loopsfm/geometry/triangulation.h"

#include <gtest/gtest.h>

#include <vector>

#include "loopsfm/geometry/pose_checks.h"
#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

Eigen::Quaterniond RandomRotation(Random& random, double max_angle_rad) {
  const Eigen::Vector3d axis =
      Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
  return Eigen::Quaterniond(Eigen::AngleAxisd(random.UniformReal(0, max_angle_rad), axis));
}

// Cameras on a circle of radius 2 around the origin at z = -6, all looking at roughly
// the origin, and a point near the origin: depths 4..8, scene size about 4.
struct Views {
  std::vector<Matrix3x4d> cams_from_world;
  std::vector<Rigid3d> poses;
};

Views MakeViews(Random& random, int num_views) {
  Views views;
  for (int i = 0; i < num_views; ++i) {
    const double phi = 2.0 * M_PI * i / num_views;
    const Eigen::Vector3d center(2.0 * std::cos(phi), 2.0 * std::sin(phi), -6.0);
    const Eigen::Quaterniond cam_from_world_rotation = RandomRotation(random, 0.1);
    Rigid3d pose(cam_from_world_rotation, -(cam_from_world_rotation * center));
    views.poses.push_back(pose);
    views.cams_from_world.push_back(pose.ToMatrix());
  }
  return views;
}

Eigen::Vector2d Project(const Rigid3d& cam_from_world, const Eigen::Vector3d& point) {
  const Eigen::Vector3d p = cam_from_world * point;
  return p.head<2>() / p.z();
}

Eigen::Vector3d RandomPoint(Random& random) {
  return {random.UniformReal(-2, 2), random.UniformReal(-2, 2), random.UniformReal(-2, 2)};
}

TEST(Triangulation, TwoViewIsExactOnNoiselessData) {
  Random random(1);
  for (int trial = 0; trial < 200; ++trial) {
    const Views views = MakeViews(random, 2);
    const Eigen::Vector3d point = RandomPoint(random);
    const auto estimate =
        TriangulatePoint(views.cams_from_world[0], views.cams_from_world[1],
                         Project(views.poses[0], point), Project(views.poses[1], point));
    ASSERT_TRUE(estimate.has_value());
    EXPECT_LT((*estimate - point).norm(), 1e-9);
  }
}

TEST(Triangulation, MultiViewIsExactOnNoiselessData) {
  Random random(2);
  for (int num_views : {2, 3, 7}) {
    for (int trial = 0; trial < 100; ++trial) {
      const Views views = MakeViews(random, num_views);
      const Eigen::Vector3d point = RandomPoint(random);
      std::vector<Eigen::Vector2d> observations;
      for (const Rigid3d& pose : views.poses) observations.push_back(Project(pose, point));
      for (int iterations : {0, 3}) {
        const auto estimate =
            TriangulateMultiView(views.cams_from_world, observations, iterations);
        ASSERT_TRUE(estimate.has_value());
        EXPECT_LT((*estimate - point).norm(), 1e-9) << num_views << " views";
      }
    }
  }
}

// Noise of 1e-3 in normalised coordinates (1 px at a focal length of 1000 px).
TEST(Triangulation, MultiViewIsAccurateUnderNoiseAndRefinementLowersTheError) {
  Random random(3);
  const double sigma = 1e-3;
  double sum_error_linear = 0.0, sum_error_refined = 0.0;
  double sum_cost_linear = 0.0, sum_cost_refined = 0.0;
  const int num_trials = 300;
  for (int trial = 0; trial < num_trials; ++trial) {
    const Views views = MakeViews(random, 6);
    const Eigen::Vector3d point = RandomPoint(random);
    std::vector<Eigen::Vector2d> observations;
    for (const Rigid3d& pose : views.poses) {
      observations.push_back(Project(pose, point) +
                             Eigen::Vector2d(random.Normal(0, sigma), random.Normal(0, sigma)));
    }
    const auto linear = TriangulateMultiView(views.cams_from_world, observations, 0);
    const auto refined = TriangulateMultiView(views.cams_from_world, observations, 5);
    ASSERT_TRUE(linear && refined);
    sum_error_linear += (*linear - point).norm();
    sum_error_refined += (*refined - point).norm();
    double cost_linear = 0.0, cost_refined = 0.0;
    for (size_t i = 0; i < views.poses.size(); ++i) {
      cost_linear += (Project(views.poses[i], *linear) - observations[i]).squaredNorm();
      cost_refined += (Project(views.poses[i], *refined) - observations[i]).squaredNorm();
    }
    EXPECT_LE(cost_refined, cost_linear * (1 + 1e-12));
    sum_cost_linear += cost_linear;
    sum_cost_refined += cost_refined;
    // Depth about 6, baseline 4: a 1e-3 ray error moves the point by millimetres.
    EXPECT_LT((*refined - point).norm(), 0.05);
  }
  EXPECT_LT(sum_error_refined / num_trials, 0.01);
  EXPECT_LT(sum_error_linear / num_trials, 0.01);
  EXPECT_LT(sum_cost_refined, sum_cost_linear);
}

TEST(Triangulation, ParallelRaysGiveNoPoint) {
  const Rigid3d cam1(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0));
  const Rigid3d cam2(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-1, 0, 0));
  const Eigen::Vector2d ray(0.1, -0.2);
  EXPECT_FALSE(TriangulatePoint(cam1.ToMatrix(), cam2.ToMatrix(), ray, ray).has_value());
  const std::vector<Matrix3x4d> cams = {cam1.ToMatrix(), cam2.ToMatrix()};
  const std::vector<Eigen::Vector2d> rays = {ray, ray};
  EXPECT_FALSE(TriangulateMultiView(cams, rays).has_value());
  EXPECT_FALSE(TriangulateMultiView(std::span(cams).first(1), std::span(rays).first(1)));
}

TEST(Triangulation, AngleOfKnownConfigurations) {
  EXPECT_NEAR(CalculateTriangulationAngle({0, 0, 0}, {1, 0, 0}, {0.5, 0, 0.5}), M_PI / 2, 1e-15);
  EXPECT_NEAR(CalculateTriangulationAngle({0, 0, 0}, {2, 0, 0}, {1, 0, std::sqrt(3.0)}),
              M_PI / 3, 1e-15);
  EXPECT_EQ(CalculateTriangulationAngle({0, 0, 0}, {0, 0, 0}, {1, 2, 3}), 0.0);
  // Small angles stay accurate: baseline 1e-6 at distance 1.
  EXPECT_NEAR(CalculateTriangulationAngle({0, 0, 0}, {1e-6, 0, 0}, {0, 0, 1}), 1e-6, 1e-18);
}

TEST(Triangulation, CheckedVariantReportsWhyAPointIsRejected) {
  const Rigid3d cam1(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 0));
  const Rigid3d cam2(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-1, 0, 0));
  const std::vector<Matrix3x4d> cams = {cam1.ToMatrix(), cam2.ToMatrix()};
  TriangulationOptions options;
  options.Check();

  const Eigen::Vector3d good(0.5, 0.2, 5.0);  // angle about 11.4 degrees
  std::vector<Eigen::Vector2d> obs = {Project(cam1, good), Project(cam2, good)};
  TriangulationReport report = TriangulateMultiViewChecked(cams, obs, options);
  EXPECT_TRUE(report.success());
  EXPECT_LT((report.point3D_in_world - good).norm(), 1e-9);
  EXPECT_NEAR(report.tri_angle_deg,
              CalculateTriangulationAngle({0, 0, 0}, {1, 0, 0}, good) * 180 / M_PI, 1e-9);
  EXPECT_LT(report.max_angular_error_deg, 1e-9);

  const Eigen::Vector3d far(0.5, 0.2, 100.0);  // angle about 0.57 degrees
  obs = {Project(cam1, far), Project(cam2, far)};
  EXPECT_EQ(TriangulateMultiViewChecked(cams, obs, options).status,
            TriangulationStatus::kSmallAngle);

  const Eigen::Vector3d behind(0.5, 0.2, -5.0);  // projects, but behind both cameras
  obs = {Project(cam1, behind), Project(cam2, behind)};
  EXPECT_EQ(TriangulateMultiViewChecked(cams, obs, options).status,
            TriangulationStatus::kNegativeDepth);

  // A third view whose observation is 0.02 (about 1.1 degrees) off.
  const Rigid3d cam3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, -1, 0));
  const std::vector<Matrix3x4d> cams3 = {cam1.ToMatrix(), cam2.ToMatrix(), cam3.ToMatrix()};
  obs = {Project(cam1, good), Project(cam2, good),
         Project(cam3, good) + Eigen::Vector2d(0.02, 0.0)};
  report = TriangulateMultiViewChecked(cams3, obs, options);
  EXPECT_EQ(report.status, TriangulationStatus::kLargeError);
  EXPECT_GT(report.max_angular_error_deg, options.max_angular_error_deg);

  options.min_tri_angle_deg = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
