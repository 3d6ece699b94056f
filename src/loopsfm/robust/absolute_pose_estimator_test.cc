#include "loopsfm/robust/absolute_pose_estimator.h"

#include <gtest/gtest.h>

#include "loopsfm/geometry/pose_checks.h"

namespace loopsfm {
namespace {

// A camera looking at points 5..15 units away (scene size about 10), observed with
// Gaussian noise of `noise` in normalised coordinates (1e-3 = 1 px at f = 1000 px) and a
// fraction of outliers (random image points).
struct Scene {
  Rigid3d cam_from_world;
  std::vector<Eigen::Vector2d> points2D;
  std::vector<Eigen::Vector3d> points3D;
  std::vector<bool> is_inlier;
};

Scene MakeScene(Random& random, int n, double outlier_ratio, double noise) {
  Scene scene;
  const Eigen::Vector3d axis =
      Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
  scene.cam_from_world = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(random.UniformReal(0, 3), axis)),
                                 Eigen::Vector3d(random.Normal(0, 5), random.Normal(0, 5),
                                                 random.Normal(0, 5)));
  const Rigid3d world_from_cam = scene.cam_from_world.Inverse();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d image(random.UniformReal(-0.5, 0.5), random.UniformReal(-0.4, 0.4));
    const double depth = random.UniformReal(5, 15);
    scene.points3D.push_back(world_from_cam * (depth * image.homogeneous()));
    const bool outlier = i < outlier_ratio * n;
    scene.is_inlier.push_back(!outlier);
    scene.points2D.push_back(outlier ? Eigen::Vector2d(random.UniformReal(-0.5, 0.5),
                                                       random.UniformReal(-0.4, 0.4))
                                     : image + Eigen::Vector2d(random.Normal(0, noise),
                                                               random.Normal(0, noise)));
  }
  return scene;
}

RansacOptions PoseOptions() {
  RansacOptions options;
  options.max_error = 4e-3;  // 4 px at f = 1000 px
  return options;
}

TEST(AbsolutePoseRansac, IsAccurateWith40PercentOutliersAnd1PxNoise) {
  double max_rotation_error = 0.0, max_center_error = 0.0;
  for (int seed = 0; seed < 20; ++seed) {
    Random data_random(200 + seed);
    const Scene scene = MakeScene(data_random, 200, 0.4, 1e-3);
    Random random(seed);
    const auto report =
        EstimateAbsolutePoseNormalized(scene.points2D, scene.points3D, PoseOptions(), random);
    ASSERT_TRUE(report.success);
    max_rotation_error =
        std::max(max_rotation_error, RotationErrorDegrees(report.model, scene.cam_from_world));
    max_center_error = std::max(max_center_error, CenterError(report.model, scene.cam_from_world));
    int missed = 0, wrong = 0;
    for (size_t i = 0; i < scene.is_inlier.size(); ++i) {
      missed += scene.is_inlier[i] && !report.inlier_mask[i];
      wrong += !scene.is_inlier[i] && report.inlier_mask[i];
    }
    EXPECT_LE(missed, 2);  // 4 px is 4 sigma per axis
    EXPECT_LE(wrong, 5);   // a few random points fall near their true projection
    EXPECT_LT(report.num_trials, 2000);
  }
  RecordProperty("max_rotation_error_deg", std::to_string(max_rotation_error));
  RecordProperty("max_center_error", std::to_string(max_center_error));
  EXPECT_LT(max_rotation_error, 0.1);
  EXPECT_LT(max_center_error, 0.01 * 10.0);  // 1% of the scene size
}

TEST(AbsolutePoseRansac, IsDeterministicForASeed) {
  Random data_random(300);
  const Scene scene = MakeScene(data_random, 150, 0.5, 1e-3);
  Random a(9), b(9);
  const auto report_a =
      EstimateAbsolutePoseNormalized(scene.points2D, scene.points3D, PoseOptions(), a);
  const auto report_b =
      EstimateAbsolutePoseNormalized(scene.points2D, scene.points3D, PoseOptions(), b);
  ASSERT_TRUE(report_a.success);
  EXPECT_EQ(report_a.num_trials, report_b.num_trials);
  EXPECT_EQ(report_a.inlier_mask, report_b.inlier_mask);
  EXPECT_EQ(report_a.model.rotation.coeffs(), report_b.model.rotation.coeffs());
  EXPECT_EQ(report_a.model.translation, report_b.model.translation);
}

TEST(AbsolutePoseRansac, ExactOnNoiselessData) {
  Random data_random(301);
  const Scene scene = MakeScene(data_random, 50, 0.0, 0.0);
  Random random(1);
  const auto report =
      EstimateAbsolutePoseNormalized(scene.points2D, scene.points3D, PoseOptions(), random);
  ASSERT_TRUE(report.success);
  EXPECT_EQ(report.num_inliers, 50);
  EXPECT_LT(RotationErrorDegrees(report.model, scene.cam_from_world), 1e-8);
  EXPECT_LT(CenterError(report.model, scene.cam_from_world), 1e-8);
}

TEST(AbsolutePoseRansac, RefinementImprovesAPerturbedPose) {
  Random data_random(302);
  const Scene scene = MakeScene(data_random, 100, 0.0, 1e-3);
  std::vector<uint32_t> all(scene.points2D.size());
  for (uint32_t i = 0; i < all.size(); ++i) all[i] = i;
  Rigid3d pose = scene.cam_from_world;
  pose.rotation = (pose.rotation *
                   Eigen::Quaterniond(Eigen::AngleAxisd(0.03, Eigen::Vector3d(1, 1, 0).normalized())))
                      .normalized();
  pose.translation += Eigen::Vector3d(0.2, -0.1, 0.3);
  const P3PEstimator estimator(scene.points2D, scene.points3D);
  std::vector<double> before, after;
  estimator.Residuals(pose, &before);
  const double rotation_error_before = RotationErrorDegrees(pose, scene.cam_from_world);
  ASSERT_TRUE(RefinePoseNormalized(scene.points2D, scene.points3D, all, &pose));
  estimator.Residuals(pose, &after);
  double cost_before = 0, cost_after = 0;
  for (size_t i = 0; i < all.size(); ++i) {
    cost_before += before[i];
    cost_after += after[i];
  }
  EXPECT_LT(cost_after, 0.01 * cost_before);
  // Noise-limited: about 2 * 100 * (1e-3)^2 at the optimum.
  EXPECT_LT(cost_after, 2 * 100 * 1e-6 * 1.5);
  EXPECT_LT(RotationErrorDegrees(pose, scene.cam_from_world), 0.05 * rotation_error_before);
  EXPECT_LT(CenterError(pose, scene.cam_from_world), 0.02);
  // Too few points.
  EXPECT_FALSE(RefinePoseNormalized(scene.points2D, scene.points3D,
                                    std::span(all).first(2), &pose));
}

}  // namespace
}  // namespace loopsfm
