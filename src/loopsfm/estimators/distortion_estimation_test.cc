#include "loopsfm/estimators/distortion_estimation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <Eigen/Geometry>

#include "loopsfm/estimators/focal_estimation.h"
#include "loopsfm/math/random.h"
#include "loopsfm/scene/camera.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

constexpr int kWidth = 640, kHeight = 360;
const Eigen::Vector2d kCentre(kWidth / 2.0, kHeight / 2.0);

// A SIMPLE_RADIAL lens: focal f, principal point at the centre, radial term k.
Camera Lens(double focal, double k) {
  Camera camera;
  camera.model_id = CameraModelId::kSimpleRadial;
  camera.width = kWidth;
  camera.height = kHeight;
  camera.params = {focal, kCentre.x(), kCentre.y(), k};
  return camera;
}

bool InImage(const Eigen::Vector2d& x) {
  return x.x() >= 0 && x.x() < kWidth && x.y() >= 0 && x.y() < kHeight;
}

// Pairs of a camera walking past a scene: each pair turned by 5..25 degrees and moved up to
// 1 unit, 150 points at depth 3..12, 0.5 px of noise; `num_outliers` wrong matches per pair.
std::vector<PairCorrespondences> MakePairs(Random& random, int num_pairs, double focal, double k,
                                           int num_outliers = 0) {
  const Camera lens = Lens(focal, k);
  std::vector<PairCorrespondences> pairs;
  while (static_cast<int>(pairs.size()) < num_pairs) {
    const Eigen::Vector3d axis = Eigen::Vector3d(random.Normal(0, 0.2), 1.0, random.Normal(0, 0.2))
                                     .normalized();
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(random.UniformReal(5, 25) * M_PI / 180.0, axis).toRotationMatrix();
    const Eigen::Vector3d t(random.UniformReal(-1, 1), random.UniformReal(-0.2, 0.2),
                            random.UniformReal(-0.5, 0.5));
    PairCorrespondences pair;
    for (int attempt = 0; attempt < 20000 && pair.points1.size() < 150; ++attempt) {
      const Eigen::Vector3d X(random.UniformReal(-8, 8), random.UniformReal(-4, 4),
                              random.UniformReal(3, 12));
      const Eigen::Vector3d in2 = R * X + t;
      if (in2.z() < 1.0) continue;
      const Eigen::Vector2d x1 = lens.ImgFromCam(X), x2 = lens.ImgFromCam(in2);
      if (!InImage(x1) || !InImage(x2)) continue;
      pair.points1.push_back(x1 + Eigen::Vector2d(random.Normal(0, 0.5), random.Normal(0, 0.5)));
      pair.points2.push_back(x2 + Eigen::Vector2d(random.Normal(0, 0.5), random.Normal(0, 0.5)));
    }
    if (pair.points1.size() < 150) continue;
    for (int i = 0; i < num_outliers; ++i) {
      pair.points1[i] = Eigen::Vector2d(random.UniformReal(0, kWidth), random.UniformReal(0, kHeight));
    }
    pairs.push_back(std::move(pair));
  }
  return pairs;
}

TEST(DistortionEstimation, UndistortionInvertsTheRadialTerm) {
  const double unit = DistortionRadiusUnit(kWidth, kHeight);
  EXPECT_DOUBLE_EQ(unit, 0.5 * std::hypot(640.0, 360.0));
  for (const double kappa : {-0.14, -0.05, 0.0, 0.1, 0.3}) {
    for (const Eigen::Vector2d undistorted :
         {Eigen::Vector2d(320, 180), Eigen::Vector2d(0, 0), Eigen::Vector2d(600, 40),
          Eigen::Vector2d(100, 300)}) {
      const Eigen::Vector2d offset = (undistorted - kCentre) / unit;
      const Eigen::Vector2d distorted =
          kCentre + unit * offset * (1.0 + kappa * offset.squaredNorm());
      Eigen::Vector2d back;
      ASSERT_TRUE(UndistortRadialPixel(distorted, kCentre, unit, kappa, &back)) << kappa;
      EXPECT_LT((back - undistorted).norm(), 1e-9) << kappa;
    }
  }
  // Past the fold-over of a strong barrel term there is no undistorted radius.
  Eigen::Vector2d back;
  EXPECT_FALSE(UndistortRadialPixel(kCentre + Eigen::Vector2d(2.0 * unit, 0), kCentre, unit, -0.14,
                                    &back));
  // kappa and SIMPLE_RADIAL's k describe the same displacement.
  EXPECT_NEAR(RadialTermForFocalLength(-0.1, 576.0, unit), -0.1 * std::pow(576.0 / unit, 2), 1e-15);
}

TEST(DistortionEstimation, RecoversABarrelLensAndWithItTheFocalLength) {
  Random random(11);
  const double focal = 576.0, k = -0.12;
  const std::vector<PairCorrespondences> pairs = MakePairs(random, 40, focal, k, 10);
  const RadialDistortionEstimate estimate =
      EstimateRadialDistortion(pairs, kCentre, kWidth, kHeight, {});
  ASSERT_TRUE(estimate.significant) << estimate.explanation;
  const double unit = DistortionRadiusUnit(kWidth, kHeight);
  EXPECT_NEAR(RadialTermForFocalLength(estimate.kappa, focal, unit), k, 0.01);
  // 0.5 px of noise on both sides leaves about 0.8 px; at kappa = 0 the border points are off
  // by several pixels.
  EXPECT_LT(estimate.error_px, 0.9 * estimate.error_px_without);
  EXPECT_EQ(estimate.num_pairs_used, 40);

  // The focal length from the undistorted pairs' F is within 1.5 % (the wrong matches, 7 % of
  // each pair, still nudge F); from the distorted ones it is not within 1.5 %.
  const FocalEstimate undistorted = EstimateSharedFocalLength(
      UndistortedFundamentals(pairs, kCentre, unit, estimate.kappa, 4.0), {}, kCentre, kWidth, kHeight,
      {});
  ASSERT_TRUE(undistorted.success) << undistorted.explanation;
  EXPECT_NEAR(undistorted.focal_px / focal, 1.0, 0.015);
  const FocalEstimate distorted = EstimateSharedFocalLength(
      UndistortedFundamentals(pairs, kCentre, unit, 0.0, 4.0), {}, kCentre, kWidth, kHeight, {});
  EXPECT_FALSE(distorted.success && std::abs(distorted.focal_px / focal - 1.0) < 0.015)
      << distorted.focal_px;
}

TEST(DistortionEstimation, AWideLensWithPincushionIsRecoveredToo) {
  Random random(12);
  const double focal = 288.0, k = 0.05;
  const std::vector<PairCorrespondences> pairs = MakePairs(random, 30, focal, k);
  const RadialDistortionEstimate estimate =
      EstimateRadialDistortion(pairs, kCentre, kWidth, kHeight, {});
  ASSERT_TRUE(estimate.significant) << estimate.explanation;
  EXPECT_NEAR(RadialTermForFocalLength(estimate.kappa, focal, DistortionRadiusUnit(kWidth, kHeight)),
              k, 0.01);
}

TEST(DistortionEstimation, ALensWithoutDistortionIsNotSignificant) {
  Random random(13);
  const std::vector<PairCorrespondences> pairs = MakePairs(random, 40, 576.0, 0.0, 10);
  const RadialDistortionEstimate estimate =
      EstimateRadialDistortion(pairs, kCentre, kWidth, kHeight, {});
  EXPECT_FALSE(estimate.significant);
  EXPECT_LT(std::abs(estimate.kappa), 0.01);
  EXPECT_NE(estimate.explanation.find("lowers the epipolar error only"), std::string::npos);
}

TEST(DistortionEstimation, TooFewPairsOrBadOptionsAreSaid) {
  Random random(14);
  const std::vector<PairCorrespondences> pairs = MakePairs(random, 3, 576.0, -0.1);
  const RadialDistortionEstimate estimate =
      EstimateRadialDistortion(pairs, kCentre, kWidth, kHeight, {});
  EXPECT_FALSE(estimate.significant);
  EXPECT_EQ(estimate.kappa, 0.0);
  EXPECT_NE(estimate.explanation.find("only 3 pairs"), std::string::npos);

  RadialDistortionOptions bad;
  bad.min_kappa = -0.2;  // folds over inside the image
  EXPECT_THROW(EstimateRadialDistortion(pairs, kCentre, kWidth, kHeight, bad), InvalidArgument);
  PairCorrespondences uneven;
  uneven.points1.resize(20);
  uneven.points2.resize(19);
  EXPECT_THROW(EstimateRadialDistortion(std::vector<PairCorrespondences>{uneven}, kCentre, kWidth,
                                        kHeight, {}),
               InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
