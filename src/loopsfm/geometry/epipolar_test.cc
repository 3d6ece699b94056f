#include "loopsfm/geometry/epipolar.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <Eigen/Geometry>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

// Pixels of random points seen by two cameras of focal length 800 (640 x 480), the second
// turned by 10 degrees and moved sideways; F = K^-T [t]x R K^-1.
struct TwoViews {
  std::vector<Eigen::Vector2d> pixels1, pixels2;
  Eigen::Matrix3d F;
};

TwoViews MakeTwoViews(Random& random, int num_points, double noise_px) {
  Eigen::Matrix3d K;
  K << 800, 0, 320, 0, 800, 240, 0, 0, 1;
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d(0.2, 1.0, 0.1).normalized())
          .toRotationMatrix();
  const Eigen::Vector3d t(1.0, 0.1, 0.2);
  TwoViews views;
  views.F = K.inverse().transpose() * Skew(t) * R * K.inverse();
  views.F /= views.F.norm();
  while (static_cast<int>(views.pixels1.size()) < num_points) {
    const Eigen::Vector3d X(random.UniformReal(-3, 3), random.UniformReal(-2, 2),
                            random.UniformReal(5, 15));
    const Eigen::Vector3d in2 = R * X + t;
    if (in2.z() <= 0) continue;
    const Eigen::Vector2d p1 = (K * X).hnormalized();
    const Eigen::Vector2d p2 = (K * in2).hnormalized();
    views.pixels1.push_back(p1 + noise_px * Eigen::Vector2d(random.Normal(), random.Normal()));
    views.pixels2.push_back(p2 + noise_px * Eigen::Vector2d(random.Normal(), random.Normal()));
  }
  return views;
}

TEST(Epipolar, EightPointsRecoverTheFundamentalMatrix) {
  Random random(7);
  const TwoViews exact = MakeTwoViews(random, 8, 0.0);
  Eigen::Matrix3d F = FundamentalFromEightPoints(exact.pixels1, exact.pixels2);
  if (F.cwiseProduct(exact.F).sum() < 0) F = -F;
  EXPECT_LT((F - exact.F).norm(), 1e-6);
  EXPECT_NEAR(F.jacobiSvd().singularValues()(2), 0.0, 1e-12);

  // With 0.5 px of noise on 200 points, the fit stays within a pixel of every point.
  const TwoViews noisy = MakeTwoViews(random, 200, 0.5);
  const Eigen::Matrix3d G = FundamentalFromEightPoints(noisy.pixels1, noisy.pixels2);
  double sum = 0.0;
  for (size_t i = 0; i < noisy.pixels1.size(); ++i) {
    sum += SampsonSquaredError(G, noisy.pixels1[i], noisy.pixels2[i]);
  }
  const double rms = std::sqrt(sum / noisy.pixels1.size());
  EXPECT_GT(rms, 0.1);  // the noise is there ...
  EXPECT_LT(rms, 0.7);  // ... and the fit is about as good as it allows
}

TEST(Epipolar, TooFewOrDegeneratePointsGiveZero) {
  Random random(8);
  const TwoViews views = MakeTwoViews(random, 7, 0.0);
  EXPECT_EQ(FundamentalFromEightPoints(views.pixels1, views.pixels2), Eigen::Matrix3d::Zero());
  std::vector<Eigen::Vector2d> same(10, Eigen::Vector2d(3, 4));
  EXPECT_EQ(FundamentalFromEightPoints(same, same), Eigen::Matrix3d::Zero());
}

TEST(Epipolar, SampsonDistanceIsTheDistanceToTheEpipolarLineForAPureTranslation) {
  // F of a sideways translation: epipolar lines are rows (y2 = y1). Moving x2 by 1.5 px
  // down puts it 1.5 px from its line; the Sampson distance splits that between both
  // points: (1.5)^2 / 2.
  Eigen::Matrix3d F;
  F << 0, 0, 0, 0, 0, -1, 0, 1, 0;
  EXPECT_NEAR(SampsonSquaredError(F, Eigen::Vector2d(10, 20), Eigen::Vector2d(40, 21.5)),
              1.5 * 1.5 / 2.0, 1e-12);
  EXPECT_NEAR(SampsonResidual(F, Eigen::Vector2d(10, 20), Eigen::Vector2d(40, 20)), 0.0, 1e-12);
}

}  // namespace
}  // namespace loopsfm
