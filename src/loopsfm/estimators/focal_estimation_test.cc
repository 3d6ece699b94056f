#include "loopsfm/estimators/focal_estimation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <fmt/format.h>
#include <gtest/gtest.h>

#include "loopsfm/geometry/epipolar.h"
#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

struct Image {
  int width = 1920;
  int height = 1080;
  Eigen::Vector2d PrincipalPoint() const { return Eigen::Vector2d(width / 2.0, height / 2.0); }
};

Eigen::Matrix3d Intrinsics(const Image& image, double focal) {
  Eigen::Matrix3d k;
  k << focal, 0, image.width / 2.0, 0, focal, image.height / 2.0, 0, 0, 1;
  return k;
}

Eigen::Vector2d Noise(Random& random, double sigma_px) {
  return Eigen::Vector2d(random.Normal(0, sigma_px), random.Normal(0, sigma_px));
}

bool InImage(const Image& image, const Eigen::Vector2d& x) {
  return x.x() >= 0 && x.x() < image.width && x.y() >= 0 && x.y() < image.height;
}

// F fitted by the 8-point algorithm to 200 noisy matches of points at depth 4..10 in front of
// camera 1 (at the origin, looking along +z) that camera 2 (cam2_from_world, centre2) sees
// too. False when camera 2 sees too few of them.
bool FitPairF(Random& random, const Image& image, double focal,
              const Eigen::Matrix3d& cam2_from_world, const Eigen::Vector3d& center2,
              double noise_px, Eigen::Matrix3d* fundamental) {
  const Eigen::Matrix3d k = Intrinsics(image, focal);
  const Eigen::Matrix3d k_inv = k.inverse();
  std::vector<Eigen::Vector2d> x1, x2;
  for (int attempt = 0; attempt < 4000 && x1.size() < 200; ++attempt) {
    const Eigen::Vector2d pixel(random.UniformReal(0, image.width),
                                random.UniformReal(0, image.height));
    const Eigen::Vector3d point = random.UniformReal(4, 10) * (k_inv * pixel.homogeneous());
    const Eigen::Vector3d in_cam2 = cam2_from_world * (point - center2);
    if (in_cam2.z() < 0.5 || !InImage(image, (k * in_cam2).hnormalized())) continue;
    x1.push_back(pixel + Noise(random, noise_px));
    x2.push_back((k * in_cam2).hnormalized() + Noise(random, noise_px));
  }
  if (x1.size() < 200) return false;
  *fundamental = FundamentalFromEightPoints(x1, x2);
  return true;
}

// F of a general two-view scene: camera 2 min..max_baseline units away, mostly to the side,
// looking at a random point of the scene with a random roll; the rotation between the views
// is in [min_angle_deg, max_angle_deg] and the optical axes do not meet.
Eigen::Matrix3d GeneralPairF(Random& random, const Image& image, double focal, double noise_px,
                             double min_baseline = 1.5, double max_baseline = 3.0,
                             double min_angle_deg = 10, double max_angle_deg = 40) {
  const Eigen::Matrix3d k_inv = Intrinsics(image, focal).inverse();
  for (;;) {
    const double azimuth = random.UniformReal(0, 2 * M_PI);
    const Eigen::Vector3d center2 =
        random.UniformReal(min_baseline, max_baseline) *
        Eigen::Vector3d(std::cos(azimuth), std::sin(azimuth), random.UniformReal(-0.3, 0.3))
            .normalized();
    const Eigen::Vector3d target =
        random.UniformReal(5, 9) *
        (k_inv * Eigen::Vector3d(random.UniformReal(0.3, 0.7) * image.width,
                                 random.UniformReal(0.3, 0.7) * image.height, 1.0));
    const Eigen::Vector3d z = (target - center2).normalized();
    const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
    Eigen::Matrix3d world_from_cam2;
    world_from_cam2 << x, z.cross(x), z;
    const Eigen::Matrix3d cam2_from_world =
        Eigen::AngleAxisd(random.UniformReal(-0.3, 0.3), Eigen::Vector3d::UnitZ())
            .toRotationMatrix() *
        world_from_cam2.transpose();
    const double angle_deg = Eigen::AngleAxisd(cam2_from_world).angle() * 180.0 / M_PI;
    if (angle_deg < min_angle_deg || angle_deg > max_angle_deg) continue;
    Eigen::Matrix3d fundamental;
    if (FitPairF(random, image, focal, cam2_from_world, center2, noise_px, &fundamental)) {
      return fundamental;
    }
  }
}

// A random rotation by an angle in [min_deg, max_deg] about a random axis.
Eigen::Matrix3d RandomRotation(Random& random, double min_deg, double max_deg) {
  const Eigen::Vector3d axis =
      Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
  const double angle = random.UniformReal(min_deg, max_deg) * M_PI / 180.0;
  return Eigen::AngleAxisd(angle, axis).toRotationMatrix();
}

// F fitted by the 8-point algorithm to a pure rotation of 5..30 degrees (x2 = K R K^-1 x1).
Eigen::Matrix3d PureRotationF(Random& random, const Image& image, double focal, double noise_px) {
  const Eigen::Matrix3d k = Intrinsics(image, focal);
  for (;;) {
    const Eigen::Matrix3d h = k * RandomRotation(random, 5, 30) * k.inverse();
    std::vector<Eigen::Vector2d> x1, x2;
    for (int attempt = 0; attempt < 4000 && x1.size() < 200; ++attempt) {
      const Eigen::Vector2d pixel(random.UniformReal(0, image.width),
                                  random.UniformReal(0, image.height));
      const Eigen::Vector3d mapped = h * pixel.homogeneous();
      if (mapped.z() <= 0 || !InImage(image, mapped.hnormalized())) continue;
      x1.push_back(pixel + Noise(random, noise_px));
      x2.push_back(mapped.hnormalized() + Noise(random, noise_px));
    }
    if (x1.size() == 200) return FundamentalFromEightPoints(x1, x2);
  }
}

// F fitted by the 8-point algorithm to 200 points of the plane z = 6 + 0.3 x, seen from a
// second camera turned by 10..30 degrees. Such an F is not unique: the fit follows the noise.
Eigen::Matrix3d PlanarSceneF(Random& random, const Image& image, double focal) {
  const Eigen::Matrix3d k = Intrinsics(image, focal);
  for (;;) {
    const Eigen::Matrix3d cam2_from_world = RandomRotation(random, 10, 30);
    const Eigen::Vector3d center2(random.Normal(), random.Normal(), 0.3 * random.Normal());
    std::vector<Eigen::Vector2d> x1, x2;
    for (int attempt = 0; attempt < 4000 && x1.size() < 200; ++attempt) {
      const Eigen::Vector2d pixel(random.UniformReal(0, image.width),
                                  random.UniformReal(0, image.height));
      const Eigen::Vector3d ray = k.inverse() * pixel.homogeneous();
      const Eigen::Vector3d in_cam2 =
          cam2_from_world * (6.0 / (1.0 - 0.3 * ray.x()) * ray - center2);
      if (in_cam2.z() < 0.5 || !InImage(image, (k * in_cam2).hnormalized())) continue;
      x1.push_back(pixel + Noise(random, 0.5));
      x2.push_back((k * in_cam2).hnormalized() + Noise(random, 0.5));
    }
    if (x1.size() == 200) return FundamentalFromEightPoints(x1, x2);
  }
}

// F fitted by the 8-point algorithm to random matches (a wrong pair).
Eigen::Matrix3d RandomMatchesF(Random& random, const Image& image) {
  std::vector<Eigen::Vector2d> x1, x2;
  for (int i = 0; i < 100; ++i) {
    x1.emplace_back(random.UniformReal(0, image.width), random.UniformReal(0, image.height));
    x2.emplace_back(random.UniformReal(0, image.width), random.UniformReal(0, image.height));
  }
  return FundamentalFromEightPoints(x1, x2);
}

// num_pairs pairs of which the first num_outliers are outliers, cycling through: random
// matches, another camera (focal x 0.6..0.8 or x 1.3..1.6), pure rotation.
std::vector<Eigen::Matrix3d> MakePairs(Random& random, const Image& image, double focal,
                                       int num_pairs, int num_outliers, double noise_px = 0.5) {
  std::vector<Eigen::Matrix3d> fs;
  for (int i = 0; i < num_pairs; ++i) {
    if (i >= num_outliers) {
      fs.push_back(GeneralPairF(random, image, focal, noise_px));
    } else if (i % 3 == 0) {
      fs.push_back(RandomMatchesF(random, image));
    } else if (i % 3 == 1) {
      const double factor = random.UniformReal(0, 1) < 0.5 ? random.UniformReal(0.6, 0.8)
                                                           : random.UniformReal(1.3, 1.6);
      fs.push_back(GeneralPairF(random, image, factor * focal, noise_px));
    } else {
      fs.push_back(PureRotationF(random, image, focal, noise_px));
    }
  }
  return fs;
}

double RelativeError(double estimate, double truth) { return std::abs(estimate / truth - 1.0); }

// The relative error of f, also recorded in the test's XML output (--gtest_output=xml).
double RecordedError(const std::string& name, double estimate, double truth) {
  const double error = RelativeError(estimate, truth);
  ::testing::Test::RecordProperty(name, std::to_string(error));
  return error;
}

// EstimateSharedFocalLength with the principal point at the image centre.
FocalEstimate Estimate(std::span<const Eigen::Matrix3d> fs, const Image& image,
                       std::span<const double> weights = {},
                       const FocalEstimationOptions& options = FocalEstimationOptions()) {
  return EstimateSharedFocalLength(fs, weights, image.PrincipalPoint(), image.width, image.height,
                                   options);
}

TEST(FocalEstimation, CostIsZeroForTheTrueFocalOnly) {
  Random random(1);
  const Image image;
  const double focal = 1.2 * 1920;
  const Eigen::Matrix3d f = GeneralPairF(random, image, focal, 0.0);
  EXPECT_LT(EssentialSingularValueCost(f, image.PrincipalPoint(), focal), 1e-6);
  EXPECT_GT(EssentialSingularValueCost(f, image.PrincipalPoint(), 0.7 * focal), 0.02);
  EXPECT_GT(EssentialSingularValueCost(f, image.PrincipalPoint(), 1.5 * focal), 0.02);
  // Invariant to the scale and sign of F.
  EXPECT_NEAR(EssentialSingularValueCost(-1e-5 * f, image.PrincipalPoint(), 0.7 * focal),
              EssentialSingularValueCost(f, image.PrincipalPoint(), 0.7 * focal), 1e-9);
  EXPECT_EQ(EssentialSingularValueCost(Eigen::Matrix3d::Zero(), image.PrincipalPoint(), focal),
            1.0);
}

// 50 pairs of a 1920 x 1080 camera with f = 1.2 x 1920, 0.5 px noise; the parameter is the
// number of outlier pairs (0, or 15 = 30 %: random matches, another focal, pure rotations).
class FocalEstimationOutlierTest : public ::testing::TestWithParam<int> {};

TEST_P(FocalEstimationOutlierTest, Recovers1920x1080FocalFrom50NoisyPairsWithinHalfAPercent) {
  const int num_outliers = GetParam();
  Random random(100 + num_outliers);
  const Image image;
  const double focal = 1.2 * 1920;
  const auto fs = MakePairs(random, image, focal, 50, num_outliers);
  const FocalEstimate estimate = Estimate(fs, image);
  ASSERT_TRUE(estimate.success) << estimate.explanation;
  EXPECT_TRUE(estimate.explanation.empty());
  EXPECT_LT(RecordedError("relative_error", estimate.focal_px, focal), 0.005);
  EXPECT_EQ(estimate.num_pairs, 50);
  EXPECT_GE(estimate.num_pairs_inlier, 45 - num_outliers);
  EXPECT_LE(estimate.num_pairs_inlier, estimate.num_pairs_used);
  // The pairs of another camera are never inliers.
  for (int i = 1; i < num_outliers; i += 3) EXPECT_FALSE(estimate.pair_is_inlier[i]) << i;
  EXPECT_LT(estimate.spread, 0.02);
}

INSTANTIATE_TEST_SUITE_P(NoneAnd30Percent, FocalEstimationOutlierTest, ::testing::Values(0, 15));

TEST(FocalEstimation, RecoversFocalsFromHalfToThreeTimesTheImageSizeInBothOrientations) {
  // 50 pairs, 30 % outliers. A longer focal (2 x 1920: 28 degrees across, 3 x: 19 degrees)
  // sees less perspective, so each pair pins f down less (about 1.3 % per pair at 3 x against
  // 0.3 % at 1.2 x): 1 % there (worst over 15 seeds: 0.40 % at 2 x, 0.56 % at 3 x).
  Random random(4);
  for (const Image image : {Image{1920, 1080}, Image{1080, 1920}}) {
    for (const double factor : {0.5, 0.8, 1.2, 2.0, 3.0}) {
      const double focal = factor * 1920;
      const auto fs = MakePairs(random, image, focal, 50, 15);
      const FocalEstimate estimate = Estimate(fs, image);
      ASSERT_TRUE(estimate.success) << estimate.explanation;
      const std::string name =
          fmt::format("relative_error_{}x{}_f{}", image.width, image.height, factor);
      EXPECT_LT(RecordedError(name, estimate.focal_px, focal), factor < 1.5 ? 0.005 : 0.01)
          << image.width << "x" << image.height << " f = " << factor << " x 1920";
    }
  }
}

TEST(FocalEstimation, PureRotationPairsVoteForTheTrueFocal) {
  // An F fitted to a pure rotation is one of the family (K R K^-1)^-T [v]x, all of them
  // valid fundamental matrices of the true K: such pairs are informative, not degenerate.
  Random random(8);
  const Image image;
  const double focal = 1.2 * 1920;
  std::vector<Eigen::Matrix3d> fs;
  for (int i = 0; i < 30; ++i) fs.push_back(PureRotationF(random, image, focal, 0.5));
  const FocalEstimate estimate = Estimate(fs, image);
  ASSERT_TRUE(estimate.success) << estimate.explanation;
  EXPECT_LT(RecordedError("relative_error", estimate.focal_px, focal), 0.005);
  EXPECT_GE(estimate.num_pairs_inlier, 15);
}

TEST(FocalEstimation, InlierCountWeightsOutvoteAMajorityOfAnotherCamera) {
  // 12 pairs of the right camera with many inliers, 20 of one other camera with few.
  Random random(5);
  const Image image;
  const double focal = 1.2 * 1920;
  std::vector<Eigen::Matrix3d> fs;
  std::vector<double> weights;
  for (int i = 0; i < 32; ++i) {
    fs.push_back(GeneralPairF(random, image, i < 12 ? focal : 0.7 * focal, 0.5));
    weights.push_back(i < 12 ? 400 : 60);
  }
  const FocalEstimationOptions options;
  const FocalEstimate weighted = Estimate(fs, image, weights, options);
  ASSERT_TRUE(weighted.success) << weighted.explanation;
  EXPECT_LT(RecordedError("weighted_relative_error", weighted.focal_px, focal), 0.005);
  EXPECT_GE(weighted.num_pairs_inlier, 10);
  for (int i = 12; i < 32; ++i) EXPECT_FALSE(weighted.pair_is_inlier[i]) << i;
  const FocalEstimate unweighted = Estimate(fs, image, {}, options);
  EXPECT_LT(RecordedError("unweighted_relative_error", unweighted.focal_px, 0.7 * focal), 0.005);
  // Pairs of weight 0 are ignored.
  std::vector<double> only_right(32, 0.0);
  std::fill(only_right.begin(), only_right.begin() + 12, 1.0);
  const FocalEstimate masked = Estimate(fs, image, only_right, options);
  ASSERT_TRUE(masked.success) << masked.explanation;
  EXPECT_LE(masked.num_pairs_used, 12);
  EXPECT_GE(masked.num_pairs_used, 10);
  EXPECT_LT(RecordedError("masked_relative_error", masked.focal_px, focal), 0.005);
}

TEST(FocalEstimation, SmallRotationsBetweenVideoFramesStillConstrainTheFocal) {
  // Neighbouring video frames: 0.2..1 units apart, turning 2..6 degrees (worst over 30 seeds:
  // 0.7 %).
  Random random(9);
  const Image image;
  const double focal = 1.2 * 1920;
  std::vector<Eigen::Matrix3d> fs;
  for (int i = 0; i < 30; ++i)
    fs.push_back(GeneralPairF(random, image, focal, 0.5, 0.2, 1.0, 2, 6));
  const FocalEstimate estimate = Estimate(fs, image);
  ASSERT_TRUE(estimate.success) << estimate.explanation;
  EXPECT_LT(RecordedError("relative_error", estimate.focal_px, focal), 0.01);
  EXPECT_GE(estimate.num_pairs_inlier, 20);
}

// 20 pairs of one degenerate kind of motion: every focal length fits them (nearly) equally
// well, so the cost curves are flat, no pair is used and the estimate fails.
class FocalEstimationDegenerateTest : public ::testing::TestWithParam<int> {};

TEST_P(FocalEstimationDegenerateTest, FailsWhenNoPairConstrainsTheFocal) {
  Random random(10 + GetParam());
  const Image image;
  const double focal = 1.2 * 1920;
  std::vector<Eigen::Matrix3d> fs;
  while (fs.size() < 20) {
    Eigen::Matrix3d cam2_from_world = Eigen::Matrix3d::Identity();
    Eigen::Vector3d center2 =
        0.3 * Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal());
    if (GetParam() == 1) {  // turning about the optical axis only (and translating)
      cam2_from_world = Eigen::AngleAxisd(random.UniformReal(0.2, 0.8), Eigen::Vector3d::UnitZ())
                            .toRotationMatrix();
    } else if (GetParam() == 2) {  // orbiting the point (0, 0, 7) while looking at it
      const Eigen::Vector3d axis =
          Eigen::Vector3d(random.Normal(), random.Normal(), 0.0).normalized();
      const Eigen::Matrix3d world_from_cam2 =
          Eigen::AngleAxisd(random.UniformReal(-0.5, 0.5), axis).toRotationMatrix();
      center2 = Eigen::Vector3d(0, 0, 7) - world_from_cam2 * Eigen::Vector3d(0, 0, 7);
      cam2_from_world = world_from_cam2.transpose();
    }  // else: pure translation, the camera does not turn
    Eigen::Matrix3d fundamental;
    if (FitPairF(random, image, focal, cam2_from_world, center2, 0.5, &fundamental)) {
      fs.push_back(fundamental);
    }
  }
  const FocalEstimate estimate = Estimate(fs, image);
  EXPECT_FALSE(estimate.success);
  EXPECT_LT(estimate.num_pairs_used, 5);
  EXPECT_NE(estimate.explanation.find("clear minimum"), std::string::npos) << estimate.explanation;
}

INSTANTIATE_TEST_SUITE_P(TranslationAxisRotationOrbit, FocalEstimationDegenerateTest,
                         ::testing::Range(0, 3));

TEST(FocalEstimation, FailsWhenAllPairsSeeOnePlane) {
  Random random(13);
  const Image image;
  std::vector<Eigen::Matrix3d> fs;
  for (int i = 0; i < 30; ++i) fs.push_back(PlanarSceneF(random, image, 1.2 * 1920));
  const FocalEstimate estimate = Estimate(fs, image);
  EXPECT_FALSE(estimate.success);
  // The pairs' estimates scatter (by 12-43 % over 20 seeds), so few agree.
  EXPECT_GT(estimate.spread, 0.1);
  EXPECT_FALSE(estimate.explanation.empty());
}

TEST(FocalEstimation, FailsOnWrongPairsAndTooFewPairs) {
  Random random(7);
  const Image image;
  const double focal = 1.2 * 1920;
  std::vector<Eigen::Matrix3d> random_fs;
  for (int i = 0; i < 40; ++i) random_fs.push_back(RandomMatchesF(random, image));
  const FocalEstimationOptions options;
  const FocalEstimate from_random = Estimate(random_fs, image, {}, options);
  EXPECT_FALSE(from_random.success);
  EXPECT_FALSE(from_random.explanation.empty());

  const auto fs = MakePairs(random, image, focal, 4, 0);  // min_num_pairs is 5
  const FocalEstimate too_few = Estimate(fs, image, {}, options);
  EXPECT_FALSE(too_few.success);
  EXPECT_NE(too_few.explanation.find("needs 5"), std::string::npos) << too_few.explanation;
  const FocalEstimate none =
      EstimateSharedFocalLength({}, {}, image.PrincipalPoint(), image.width, image.height, options);
  EXPECT_FALSE(none.success);
  EXPECT_EQ(none.focal_px, 0.0);
  EXPECT_FALSE(none.explanation.empty());
  FocalEstimationOptions three = options;
  three.min_num_pairs = 3;
  EXPECT_TRUE(Estimate(fs, image, {}, three).success);
}

TEST(FocalEstimation, RejectsBadOptionsAndInputs) {
  EXPECT_NO_THROW(FocalEstimationOptions().Check());
  auto rejects = [](auto change) {
    FocalEstimationOptions options;
    change(options);
    EXPECT_THROW(options.Check(), InvalidArgument);
  };
  rejects([](auto& o) { o.min_focal_factor = 0.0; });
  rejects([](auto& o) { o.max_focal_factor = 0.2; });
  rejects([](auto& o) { o.max_focal_factor = INFINITY; });
  rejects([](auto& o) { o.num_grid_samples = 3; });
  rejects([](auto& o) { o.max_pair_cost = 0.0; });
  rejects([](auto& o) { o.max_pair_cost = 1.5; });
  rejects([](auto& o) { o.min_cost_rise = -0.1; });
  rejects([](auto& o) { o.min_cost_rise_ratio = NAN; });
  rejects([](auto& o) { o.ambiguity_log_distance = 0.0; });
  rejects([](auto& o) { o.inlier_log_tolerance = -1.0; });
  rejects([](auto& o) { o.min_num_pairs = 0; });
  rejects([](auto& o) { o.min_inlier_ratio = 1.5; });
  rejects([](auto& o) { o.max_spread = 0.0; });
  rejects([](auto& o) { o.refine_tolerance = 0.0; });

  const std::vector<Eigen::Matrix3d> fs(3, Eigen::Matrix3d::Identity());
  const Eigen::Vector2d center(960, 540);
  const FocalEstimationOptions options;
  const std::vector<double> two_weights = {1.0, 2.0};
  EXPECT_THROW(EstimateSharedFocalLength(fs, two_weights, center, 1920, 1080, options),
               InvalidArgument);
  const std::vector<double> negative = {1.0, -2.0, 1.0};
  EXPECT_THROW(EstimateSharedFocalLength(fs, negative, center, 1920, 1080, options),
               InvalidArgument);
  EXPECT_THROW(EstimateSharedFocalLength(fs, {}, center, 0, 1080, options), InvalidArgument);
  FocalEstimationOptions bad = options;
  bad.num_grid_samples = 0;
  EXPECT_THROW(EstimateSharedFocalLength(fs, {}, center, 1920, 1080, bad), InvalidArgument);
}

// Accuracy over 100 random problems (50 pairs of 200 matches, 0.5 px noise, f = 0.5 .. 3 x
// 1920 on 1920 x 1080), without and with 30 % outlier pairs. Slow (about 5 s): run with
// --gtest_also_run_disabled_tests. Measured (relative error of f):
//   no outliers:   median 0.06 %, 90th percentile 0.20 %, max 0.32 % (at f = 2.5 x), no failures
//   30 % outliers: median 0.08 %, 90th percentile 0.22 %, max 0.38 % (at f = 2.6 x), no failures
TEST(FocalEstimation, DISABLED_AccuracyOver100RandomProblems) {
  const Image image;
  for (const int num_outliers : {0, 15}) {
    std::vector<std::pair<double, double>> errors;  // (relative error, focal factor)
    int failures = 0;
    for (int problem = 0; problem < 100; ++problem) {
      Random random(1000 + problem);
      const double factor = random.UniformReal(0.5, 3.0);
      const auto fs = MakePairs(random, image, factor * 1920, 50, num_outliers);
      const FocalEstimate estimate = Estimate(fs, image);
      failures += !estimate.success;
      errors.emplace_back(RelativeError(estimate.focal_px, factor * 1920), factor);
    }
    std::sort(errors.begin(), errors.end());
    std::printf(
        "%d %% outliers: median relative error %.3f %%, 90th percentile %.3f %%, "
        "max %.3f %% (f = %.2f x 1920), %d failures\n",
        2 * num_outliers, 100 * errors[50].first, 100 * errors[90].first, 100 * errors[99].first,
        errors[99].second, failures);
    EXPECT_EQ(failures, 0);
    EXPECT_LT(errors[50].first, 0.002);
    EXPECT_LT(errors[90].first, 0.005);
    EXPECT_LT(errors[99].first, 0.01);
  }
}

}  // namespace
}  // namespace loopsfm
