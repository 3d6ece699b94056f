#include "loopsfm/estimators/bearing_rays.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <ceres/loss_function.h>

#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

Eigen::Vector3d RandomUnit(Random& random) {
  return Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
}

// Rays from random origins around the origin through `point`.
std::vector<BearingRay> RaysThrough(const Eigen::Vector3d& point, int n, Random& random) {
  std::vector<BearingRay> rays;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d origin = 3.0 * RandomUnit(random);
    rays.push_back({origin, (point - origin).normalized()});
  }
  return rays;
}

TEST(BearingRays, AngleBetween) {
  EXPECT_NEAR(AngleBetween(Eigen::Vector3d::UnitX(), Eigen::Vector3d(0, 2, 0)), M_PI / 2, 1e-12);
  EXPECT_NEAR(AngleBetween(Eigen::Vector3d::UnitX(), Eigen::Vector3d(5, 0, 0)), 0.0, 1e-12);
  EXPECT_NEAR(AngleBetween(Eigen::Vector3d::UnitX(), Eigen::Vector3d(-1, 0, 0)), M_PI, 1e-12);
  EXPECT_NEAR(AngleBetween(Eigen::Vector3d::UnitX(), Eigen::Vector3d(1, 1, 0)), M_PI / 4, 1e-12);
  EXPECT_EQ(AngleBetween(Eigen::Vector3d::UnitX(), Eigen::Vector3d::Zero()), M_PI);
}

TEST(BearingRays, IntersectsExactRaysAtTheirPoint) {
  Random random(1);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Vector3d point(random.Normal(), random.Normal(), 10.0 + random.Normal());
    const std::vector<BearingRay> rays = RaysThrough(point, 2 + trial % 5, random);
    const std::optional<Eigen::Vector3d> found = IntersectRays(rays);
    ASSERT_TRUE(found.has_value());
    EXPECT_LT((*found - point).norm(), 1e-9);
  }
}

TEST(BearingRays, ParallelOrTooFewRaysHaveNoIntersection) {
  const BearingRay a{Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()};
  const BearingRay b{Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ()};
  EXPECT_FALSE(IntersectRays(std::vector<BearingRay>{a, b}).has_value());
  EXPECT_FALSE(IntersectRays(std::vector<BearingRay>{a}).has_value());
  const BearingRay c{Eigen::Vector3d::UnitX(), Eigen::Vector3d(-1, 0, 1).normalized()};
  const std::optional<Eigen::Vector3d> meet = IntersectRays(std::vector<BearingRay>{a, c});
  ASSERT_TRUE(meet.has_value());
  EXPECT_LT((*meet - Eigen::Vector3d(0, 0, 1)).norm(), 1e-12);
}

TEST(BearingRays, FitCountsInliersAndCapsRaysPointingAway) {
  const Eigen::Vector3d point(0, 0, 1);
  const std::vector<BearingRay> rays = {
      {Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()},                        // exact
      {Eigen::Vector3d::Zero(), Eigen::Vector3d(std::sin(0.1), 0, std::cos(0.1))},  // 0.1 rad
      {Eigen::Vector3d::Zero(), -Eigen::Vector3d::UnitZ()},                       // away
  };
  const RayFit plain = FitRays(point, rays, nullptr, 0.05);
  EXPECT_EQ(plain.num_inliers, 1);
  EXPECT_NEAR(plain.cost, std::pow(std::sin(0.1), 2) + 1.0, 1e-12);
  const ceres::HuberLoss huber(0.1);
  const RayFit robust = FitRays(point, rays, &huber, 0.2);
  EXPECT_EQ(robust.num_inliers, 2);
  // Huber: s below 0.01, 2 * 0.1 * sqrt(s) - 0.01 above.
  EXPECT_NEAR(robust.cost, std::pow(std::sin(0.1), 2) + (0.2 - 0.01), 1e-12);
  EXPECT_TRUE((RayFit{2, 5.0}).BetterThan(RayFit{1, 0.0}));
  EXPECT_TRUE((RayFit{2, 0.5}).BetterThan(RayFit{2, 1.0}));
  EXPECT_FALSE((RayFit{2, 1.0}).BetterThan(RayFit{2, 0.5}));
}

TEST(BearingRays, BestIntersectionIgnoresOutlierRays) {
  Random random(2);
  const ceres::CauchyLoss cauchy(0.05);
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::Vector3d point(random.Normal(), random.Normal(), 10.0);
    std::vector<BearingRay> rays = RaysThrough(point, 6, random);
    // Two rays turned to random directions.
    rays[1].direction = RandomUnit(random);
    rays[4].direction = RandomUnit(random);
    const auto best = BestRayIntersection(rays, &cauchy, 0.01);
    ASSERT_TRUE(best.has_value());
    EXPECT_LT((best->first - point).norm(), 1e-9);
    EXPECT_EQ(best->second.num_inliers, 4);
    // The intersection of all rays is pulled away by the outliers.
    const std::optional<Eigen::Vector3d> all = IntersectRays(rays);
    ASSERT_TRUE(all.has_value());
    EXPECT_GT((*all - point).norm(), 1e-3);
  }
}

}  // namespace
}  // namespace loopsfm
