#include "loopsfm/matching/relative_pose_refinement.h"

#include <gtest/gtest.h>

#include <cmath>

#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

Eigen::Vector3d RandomUnit(Random& random) {
  return Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
}

// Normalised correspondences of random points seen by cam1 = identity and cam2_from_cam1.
void MakeCorrespondences(const Rigid3d& cam2_from_cam1, int n, double noise, Random& random,
                         std::vector<Eigen::Vector2d>* points1,
                         std::vector<Eigen::Vector2d>* points2) {
  while (static_cast<int>(points1->size()) < n) {
    const Eigen::Vector3d x(random.UniformReal(-2, 2), random.UniformReal(-2, 2),
                            random.UniformReal(4, 8));
    const Eigen::Vector3d y = cam2_from_cam1 * x;
    if (y.z() < 0.5) continue;
    points1->push_back(x.hnormalized() + noise * Eigen::Vector2d(random.Normal(), random.Normal()));
    points2->push_back(y.hnormalized() + noise * Eigen::Vector2d(random.Normal(), random.Normal()));
  }
}

TEST(RelativePoseRefinement, EssentialFromPoseSatisfiesEpipolarConstraint) {
  Random random(1);
  const Rigid3d pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, RandomUnit(random))),
                     RandomUnit(random));
  std::vector<Eigen::Vector2d> p1, p2;
  MakeCorrespondences(pose, 50, 0.0, random, &p1, &p2);
  const Eigen::Matrix3d E = EssentialFromPose(pose);
  for (size_t i = 0; i < p1.size(); ++i) {
    EXPECT_NEAR(p2[i].homogeneous().dot(E * p1[i].homogeneous()), 0.0, 1e-12);
    EXPECT_LT(SampsonSquaredError(E, p1[i], p2[i]), 1e-24);
  }
  // Moving x2 by d across its epipolar line l2 = E x1: the Sampson distance is
  // d |l2_xy| / sqrt(|l2_xy|^2 + |l1_xy|^2) with l1 = E^T x2 (the error is shared by both).
  const Eigen::Vector3d l2 = E * p1[0].homogeneous();
  const double d = 1e-3;
  const Eigen::Vector2d moved = p2[0] + d * l2.head<2>().normalized();
  const Eigen::Vector3d l1 = E.transpose() * moved.homogeneous();
  const double expected =
      d * l2.head<2>().norm() / std::hypot(l2.head<2>().norm(), l1.head<2>().norm());
  EXPECT_NEAR(std::sqrt(SampsonSquaredError(E, p1[0], moved)), expected, 1e-12);
}

TEST(RelativePoseRefinement, ConvergesToTheTruePoseFromAPerturbedStart) {
  Random random(2);
  for (int trial = 0; trial < 10; ++trial) {
    const Rigid3d truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.2, RandomUnit(random))),
                        RandomUnit(random));
    std::vector<Eigen::Vector2d> p1, p2;
    MakeCorrespondences(truth, 100, 0.0, random, &p1, &p2);
    // Start 2 degrees off in rotation and about 3 degrees off in translation direction.
    const Rigid3d start(
        Eigen::Quaterniond(Eigen::AngleAxisd(2.0 * M_PI / 180, RandomUnit(random))) *
            truth.rotation,
        (truth.translation + 0.05 * RandomUnit(random)).normalized());
    const Rigid3d refined = RefineRelativePose(p1, p2, start, 1e-3, 50);
    EXPECT_LT(RotationAngleDegrees(refined.rotation * truth.rotation.inverse()), 1e-6);
    EXPECT_LT((refined.translation - truth.translation).norm(), 1e-6);
    EXPECT_NEAR(refined.translation.norm(), 1.0, 1e-12);
  }
}

TEST(RelativePoseRefinement, CauchyLossResistsAFewOutliers) {
  Random random(3);
  const Rigid3d truth(Eigen::Quaterniond(Eigen::AngleAxisd(0.2, RandomUnit(random))),
                      RandomUnit(random));
  std::vector<Eigen::Vector2d> p1, p2;
  MakeCorrespondences(truth, 200, 1e-3, random, &p1, &p2);  // about 0.6 px at f = 600
  const std::vector<Eigen::Vector2d> clean1(p1.begin() + 10, p1.end());
  const std::vector<Eigen::Vector2d> clean2(p2.begin() + 10, p2.end());
  for (int i = 0; i < 10; ++i) p2[i] += Eigen::Vector2d(0.05, -0.03);  // 5% gross outliers
  auto rotation_error = [&](const Rigid3d& pose) {
    return RotationAngleDegrees(pose.rotation * truth.rotation.inverse());
  };
  auto translation_error = [&](const Rigid3d& pose) {
    return std::acos(std::min(1.0, pose.translation.dot(truth.translation))) * 180 / M_PI;
  };
  const Rigid3d robust = RefineRelativePose(p1, p2, truth, 2e-3);
  const Rigid3d least_squares = RefineRelativePose(p1, p2, truth, 10.0);  // loss ~ quadratic
  const Rigid3d clean = RefineRelativePose(clean1, clean2, truth, 2e-3);
  // With the Cauchy loss the outliers barely move the estimate from the one without them;
  // least squares is pulled away.
  EXPECT_LT(RotationAngleDegrees(robust.rotation * clean.rotation.inverse()), 0.02);
  EXPECT_LT(std::acos(std::min(1.0, robust.translation.dot(clean.translation))) * 180 / M_PI,
            0.05);
  EXPECT_GT(rotation_error(least_squares), 2 * rotation_error(robust));
  EXPECT_GT(translation_error(least_squares), 2 * translation_error(robust));
  EXPECT_LT(rotation_error(robust), 0.5);
  EXPECT_LT(translation_error(robust), 2.0);
}

TEST(RelativePoseRefinement, TooFewPointsReturnTheStart) {
  const Rigid3d start(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0, 0));
  const std::vector<Eigen::Vector2d> p(4, Eigen::Vector2d(0.1, 0.2));
  const Rigid3d refined = RefineRelativePose(p, p, start, 1e-3);
  EXPECT_EQ(refined.translation, start.translation);
}

}  // namespace
}  // namespace loopsfm
