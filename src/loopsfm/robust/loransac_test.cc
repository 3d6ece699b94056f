#include "loopsfm/robust/loransac.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/Dense>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Line y = slope * x + offset from 2D points; the residual is the vertical distance.
struct Line {
  double slope = 0, offset = 0;
};

class LineEstimator {
 public:
  using Model = Line;
  static constexpr int kMinNumSamples = 2;
  explicit LineEstimator(const std::vector<Eigen::Vector2d>& points) : points_(points) {}
  size_t NumData() const { return points_.size(); }
  std::vector<Line> Estimate(std::span<const uint32_t> sample) const {
    const Eigen::Vector2d& a = points_[sample[0]];
    const Eigen::Vector2d& b = points_[sample[1]];
    if (a.x() == b.x()) return {};
    const double slope = (b.y() - a.y()) / (b.x() - a.x());
    return {Line{slope, a.y() - slope * a.x()}};
  }
  void Residuals(const Line& line, std::vector<double>* residuals) const {
    residuals->resize(points_.size());
    for (size_t i = 0; i < points_.size(); ++i) {
      const double r = points_[i].y() - (line.slope * points_[i].x() + line.offset);
      (*residuals)[i] = r * r;
    }
  }

 protected:
  const std::vector<Eigen::Vector2d>& points_;
};

// Adds a least-squares fit as the local optimisation.
class LocallyOptimizedLineEstimator : public LineEstimator {
 public:
  using LineEstimator::LineEstimator;
  bool EstimateNonMinimal(std::span<const uint32_t> inliers, Line* line) const {
    Eigen::MatrixXd a(inliers.size(), 2);
    Eigen::VectorXd b(inliers.size());
    for (size_t k = 0; k < inliers.size(); ++k) {
      a(k, 0) = points_[inliers[k]].x();
      a(k, 1) = 1.0;
      b(k) = points_[inliers[k]].y();
    }
    const Eigen::Vector2d fit = a.colPivHouseholderQr().solve(b);
    *line = Line{fit(0), fit(1)};
    return fit.allFinite();
  }
};

static_assert(RansacEstimator<LineEstimator>);
static_assert(!LocallyOptimizableEstimator<LineEstimator>);
static_assert(LocallyOptimizableEstimator<LocallyOptimizedLineEstimator>);

// Points on y = 2x - 1 with Gaussian noise, and a fraction of uniform outliers.
std::vector<Eigen::Vector2d> MakeLineData(Random& random, int n, double outlier_ratio,
                                          double noise, std::vector<bool>* is_inlier) {
  std::vector<Eigen::Vector2d> points;
  is_inlier->clear();
  for (int i = 0; i < n; ++i) {
    const double x = random.UniformReal(-10, 10);
    const bool outlier = i < outlier_ratio * n;
    const double y = outlier ? random.UniformReal(-40, 40) : 2 * x - 1 + random.Normal(0, noise);
    points.emplace_back(x, y);
    is_inlier->push_back(!outlier);
  }
  return points;
}

RansacOptions LineOptions() {
  RansacOptions options;
  options.max_error = 0.3;
  return options;
}

TEST(LoRansac, FitsALineWithHalfTheDataOutliers) {
  Random data_random(1);
  std::vector<bool> is_inlier;
  const auto points = MakeLineData(data_random, 400, 0.5, 0.05, &is_inlier);
  const LocallyOptimizedLineEstimator estimator(points);
  Random random(2);
  const auto report = LoRansac(estimator, LineOptions(), random);
  ASSERT_TRUE(report.success);
  EXPECT_NEAR(report.model.slope, 2.0, 0.01);
  EXPECT_NEAR(report.model.offset, -1.0, 0.02);
  EXPECT_GT(report.num_local_optimizations, 0);
  ASSERT_EQ(report.inlier_mask.size(), points.size());
  int true_inliers_found = 0, num_true_inliers = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    if (is_inlier[i]) {
      ++num_true_inliers;
      true_inliers_found += report.inlier_mask[i];
    }
  }
  EXPECT_GE(true_inliers_found, num_true_inliers - 1);  // 0.3 is 6 sigma
  EXPECT_LE(report.num_inliers, num_true_inliers + 10);  // a few outliers fall on the line
  EXPECT_EQ(report.num_inliers,
            std::count(report.inlier_mask.begin(), report.inlier_mask.end(), 1));
}

TEST(LoRansac, IsDeterministicForASeed) {
  Random data_random(3);
  std::vector<bool> is_inlier;
  const auto points = MakeLineData(data_random, 300, 0.6, 0.05, &is_inlier);
  const LocallyOptimizedLineEstimator estimator(points);
  Random a(77), b(77), c(78);
  const auto report_a = LoRansac(estimator, LineOptions(), a);
  const auto report_b = LoRansac(estimator, LineOptions(), b);
  const auto report_c = LoRansac(estimator, LineOptions(), c);
  EXPECT_EQ(report_a.num_trials, report_b.num_trials);
  EXPECT_EQ(report_a.inlier_mask, report_b.inlier_mask);
  EXPECT_EQ(report_a.model.slope, report_b.model.slope);
  EXPECT_EQ(report_a.model.offset, report_b.model.offset);
  // Another seed draws other samples, yet finds the same line.
  EXPECT_TRUE(report_c.success);
  EXPECT_NEAR(report_c.model.slope, 2.0, 0.01);
}

TEST(LoRansac, NumberOfTrialsAdaptsToTheInlierRatio) {
  // log(0.01) / log(1 - 0.5^2) = 16.01, times 1.
  EXPECT_EQ(RansacNumTrials(0.5, 2, 0.99, 1.0, 1000), 17);
  EXPECT_EQ(RansacNumTrials(0.5, 2, 0.99, 3.0, 1000), 49);
  EXPECT_EQ(RansacNumTrials(1.0, 3, 0.99, 3.0, 1000), 1);
  EXPECT_EQ(RansacNumTrials(0.0, 3, 0.99, 3.0, 1000), 1000);
  EXPECT_EQ(RansacNumTrials(1e-3, 3, 0.9999, 3.0, 5000), 5000);

  Random data_random(4);
  std::vector<bool> is_inlier;
  RansacOptions options = LineOptions();
  // No outliers: the first all-inlier model ends the run.
  const auto clean = MakeLineData(data_random, 200, 0.0, 0.05, &is_inlier);
  Random random(5);
  EXPECT_EQ(LoRansac(LocallyOptimizedLineEstimator(clean), options, random).num_trials, 1);
  // 70% outliers: about 3 * log(1e-4) / log(1 - 0.09) = 292 trials, far below the cap.
  const auto dirty = MakeLineData(data_random, 200, 0.7, 0.05, &is_inlier);
  const auto report = LoRansac(LocallyOptimizedLineEstimator(dirty), options, random);
  EXPECT_TRUE(report.success);
  EXPECT_GT(report.num_trials, 150);
  EXPECT_LT(report.num_trials, 600);
  // The cap holds.
  options.max_num_trials = 20;
  EXPECT_LE(LoRansac(LocallyOptimizedLineEstimator(dirty), options, random).num_trials, 20);
  // min_num_trials holds when there are outliers.
  options.max_num_trials = 10000;
  options.min_num_trials = 1000;
  EXPECT_GE(LoRansac(LocallyOptimizedLineEstimator(dirty), options, random).num_trials, 1000);
}

TEST(LoRansac, LocalOptimisationImprovesAccuracy) {
  double error_plain = 0.0, error_lo = 0.0;
  for (int seed = 0; seed < 30; ++seed) {
    Random data_random(100 + seed);
    std::vector<bool> is_inlier;
    const auto points = MakeLineData(data_random, 200, 0.5, 0.1, &is_inlier);
    RansacOptions options = LineOptions();
    options.max_error = 0.5;
    Random random_plain(seed), random_lo(seed);
    const auto plain = LoRansac(LineEstimator(points), options, random_plain);
    const auto lo = LoRansac(LocallyOptimizedLineEstimator(points), options, random_lo);
    ASSERT_TRUE(plain.success && lo.success);
    EXPECT_EQ(plain.num_local_optimizations, 0);
    error_plain += std::abs(plain.model.slope - 2.0);
    error_lo += std::abs(lo.model.slope - 2.0);
  }
  EXPECT_LT(error_lo, 0.7 * error_plain);
}

TEST(LoRansac, FailsWithTooLittleDataAndChecksOptions) {
  const std::vector<Eigen::Vector2d> one = {{0.0, 1.0}};
  Random random(6);
  const auto report = LoRansac(LineEstimator(one), LineOptions(), random);
  EXPECT_FALSE(report.success);
  EXPECT_EQ(report.num_trials, 0);

  RansacOptions options;  // max_error left at 0
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = LineOptions();
  options.confidence = 1.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = LineOptions();
  options.min_num_trials = 50;
  options.max_num_trials = 10;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
