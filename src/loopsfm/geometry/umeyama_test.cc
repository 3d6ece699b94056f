#include "loopsfm/geometry/umeyama.h"

#include <gtest/gtest.h>

#include <vector>

#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

Eigen::Quaterniond RandomRotation(Random& random) {
  return Eigen::Quaterniond(random.Normal(), random.Normal(), random.Normal(), random.Normal())
      .normalized();
}

std::vector<Eigen::Vector3d> RandomPoints(Random& random, int n, double extent) {
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < n; ++i) {
    points.emplace_back(random.UniformReal(-extent, extent), random.UniformReal(-extent, extent),
                        random.UniformReal(-extent, extent));
  }
  return points;
}

TEST(Umeyama, RecoversAKnownSim3Exactly) {
  Random random(11);
  for (int trial = 0; trial < 100; ++trial) {
    Sim3d truth;
    truth.scale = std::exp(random.UniformReal(-3, 3));
    truth.rotation = RandomRotation(random);
    truth.translation = Eigen::Vector3d(random.Normal(0, 10), random.Normal(0, 10),
                                        random.Normal(0, 10));
    const int n = trial % 2 == 0 ? 3 : 50;
    const std::vector<Eigen::Vector3d> src = RandomPoints(random, n, 5.0);
    std::vector<Eigen::Vector3d> dst;
    for (const auto& p : src) dst.push_back(truth * p);
    const std::optional<Sim3d> estimate = EstimateSim3(src, dst);
    ASSERT_TRUE(estimate.has_value());
    EXPECT_NEAR(estimate->scale, truth.scale, 1e-9 * truth.scale);
    EXPECT_LT(estimate->rotation.angularDistance(truth.rotation), 1e-9);
    EXPECT_LT((estimate->translation - truth.translation).norm(), 1e-9 * (1 + truth.scale));
    for (size_t i = 0; i < src.size(); ++i) {
      EXPECT_LT((*estimate * src[i] - dst[i]).norm(), 1e-9 * (1 + truth.scale));
    }
  }
}

TEST(Sim3d, InverseUndoesTheTransform) {
  Random random(13);
  Sim3d b_from_a;
  b_from_a.scale = 3.7;
  b_from_a.rotation = RandomRotation(random);
  b_from_a.translation = Eigen::Vector3d(4, -1, 2);
  const Sim3d a_from_b = b_from_a.Inverse();
  for (const Eigen::Vector3d& x : RandomPoints(random, 20, 10.0)) {
    EXPECT_LT((a_from_b * (b_from_a * x) - x).norm(), 1e-12 * (1 + x.norm()));
  }
  EXPECT_NEAR(a_from_b.scale * b_from_a.scale, 1.0, 1e-15);
}

TEST(Umeyama, RigidVariantKeepsScaleOne) {
  Random random(12);
  const Rigid3d truth(RandomRotation(random), Eigen::Vector3d(1, -2, 3));
  const std::vector<Eigen::Vector3d> src = RandomPoints(random, 10, 2.0);
  std::vector<Eigen::Vector3d> dst;
  for (const auto& p : src) dst.push_back(truth * p);
  const std::optional<Rigid3d> estimate = EstimateRigid3(src, dst);
  ASSERT_TRUE(estimate.has_value());
  EXPECT_LT(estimate->rotation.angularDistance(truth.rotation), 1e-12);
  EXPECT_LT((estimate->translation - truth.translation).norm(), 1e-12);
}

TEST(Umeyama, IsAccurateUnderNoise) {
  Random random(13);
  Sim3d truth;
  truth.scale = 2.5;
  truth.rotation = RandomRotation(random);
  truth.translation = Eigen::Vector3d(3, 1, -4);
  const std::vector<Eigen::Vector3d> src = RandomPoints(random, 500, 10.0);
  std::vector<Eigen::Vector3d> dst;
  const double sigma = 0.05;  // 0.2% of the (scaled) extent
  for (const auto& p : src) {
    dst.push_back(truth * p +
                  Eigen::Vector3d(random.Normal(0, sigma), random.Normal(0, sigma),
                                  random.Normal(0, sigma)));
  }
  const std::optional<Sim3d> estimate = EstimateSim3(src, dst);
  ASSERT_TRUE(estimate.has_value());
  EXPECT_NEAR(estimate->scale, truth.scale, 1e-3 * truth.scale);
  EXPECT_LT(estimate->rotation.angularDistance(truth.rotation) * 180 / M_PI, 0.02);
  EXPECT_LT((estimate->translation - truth.translation).norm(), 0.02);
  double rms = 0.0;
  for (size_t i = 0; i < src.size(); ++i) rms += (*estimate * src[i] - dst[i]).squaredNorm();
  rms = std::sqrt(rms / src.size());
  EXPECT_LT(rms, 1.05 * std::sqrt(3.0) * sigma);
}

TEST(Umeyama, MirroredPointsStillGiveARotation) {
  Random random(14);
  const std::vector<Eigen::Vector3d> src = RandomPoints(random, 20, 1.0);
  std::vector<Eigen::Vector3d> dst;
  for (const auto& p : src) dst.emplace_back(p.x(), p.y(), -p.z());
  const std::optional<Sim3d> estimate = EstimateSim3(src, dst);
  ASSERT_TRUE(estimate.has_value());
  EXPECT_NEAR(estimate->rotation.toRotationMatrix().determinant(), 1.0, 1e-12);
}

TEST(Umeyama, RejectsDegenerateInput) {
  Random random(15);
  const std::vector<Eigen::Vector3d> two = RandomPoints(random, 2, 1.0);
  EXPECT_FALSE(EstimateSim3(two, two).has_value());
  const std::vector<Eigen::Vector3d> three = RandomPoints(random, 3, 1.0);
  EXPECT_FALSE(EstimateSim3(three, two).has_value());  // sizes differ

  std::vector<Eigen::Vector3d> collinear;
  for (int i = 0; i < 10; ++i) collinear.push_back(Eigen::Vector3d(1, 2, 3) * (0.3 * i - 1.0));
  std::vector<Eigen::Vector3d> moved;
  for (const auto& p : collinear) moved.push_back(p + Eigen::Vector3d(1, 0, 0));
  EXPECT_FALSE(EstimateSim3(collinear, moved).has_value());
  EXPECT_FALSE(EstimateRigid3(collinear, moved).has_value());

  const std::vector<Eigen::Vector3d> spread = RandomPoints(random, 10, 1.0);
  EXPECT_FALSE(EstimateSim3(spread, collinear).has_value());  // dst collinear
  const std::vector<Eigen::Vector3d> same(10, Eigen::Vector3d(1, 1, 1));
  EXPECT_FALSE(EstimateSim3(same, spread).has_value());  // src coincident
  EXPECT_FALSE(EstimateSim3(spread, same).has_value());  // dst coincident

  std::vector<Eigen::Vector3d> with_nan = spread;
  with_nan[3].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(EstimateSim3(with_nan, spread).has_value());
}

}  // namespace
}  // namespace loopsfm
