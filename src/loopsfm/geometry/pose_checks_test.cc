#include "loopsfm/geometry/pose_checks.h"

#include <gtest/gtest.h>

#include <vector>

#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

Rigid3d ExamplePose() {
  const Eigen::Quaterniond rotation(
      Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  return Rigid3d(rotation, Eigen::Vector3d(0.2, -0.1, 3.0));
}

TEST(PoseChecks, DepthAndCheirality) {
  const Rigid3d cam_from_world = ExamplePose();
  const Eigen::Vector3d center = ProjectionCenter(cam_from_world);
  EXPECT_LT((cam_from_world * center).norm(), 1e-15);
  // Optical axis in world coordinates.
  const Eigen::Vector3d axis = cam_from_world.rotation.inverse() * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d in_front = center + 2.5 * axis + Eigen::Vector3d(0.1, 0.0, 0.0);
  const Eigen::Vector3d behind = center - 2.5 * axis;
  EXPECT_NEAR(CalculateDepth(cam_from_world.ToMatrix(), center + 2.5 * axis), 2.5, 1e-12);
  EXPECT_TRUE(HasPointPositiveDepth(cam_from_world, in_front));
  EXPECT_TRUE(HasPointPositiveDepth(cam_from_world.ToMatrix(), in_front));
  EXPECT_FALSE(HasPointPositiveDepth(cam_from_world, behind));
  EXPECT_FALSE(HasPointPositiveDepth(cam_from_world.ToMatrix(), behind));
  EXPECT_FALSE(HasPointPositiveDepth(cam_from_world, center));
}

TEST(PoseChecks, ReprojectionAndAngularErrors) {
  const Rigid3d cam_from_world = ExamplePose();
  const Eigen::Vector3d point = cam_from_world.Inverse() * Eigen::Vector3d(0.4, -0.2, 2.0);
  const Eigen::Vector2d exact(0.2, -0.1);
  EXPECT_LT(CalculateSquaredNormalizedReprojectionError(exact, point, cam_from_world), 1e-28);
  EXPECT_NEAR(CalculateSquaredNormalizedReprojectionError(exact + Eigen::Vector2d(0.03, 0.04),
                                                          point, cam_from_world),
              0.0025, 1e-14);
  EXPECT_LT(CalculateAngularError(exact, point, cam_from_world), 1e-14);
  // The ray (0,0,1) against the point at 45 degrees in the x-z plane.
  const Eigen::Vector3d diagonal = cam_from_world.Inverse() * Eigen::Vector3d(1.0, 0.0, 1.0);
  EXPECT_NEAR(CalculateAngularError({0, 0}, diagonal, cam_from_world), M_PI / 4, 1e-14);
  const Eigen::Vector3d behind = cam_from_world.Inverse() * Eigen::Vector3d(0.4, -0.2, -2.0);
  EXPECT_EQ(CalculateSquaredNormalizedReprojectionError(exact, behind, cam_from_world),
            std::numeric_limits<double>::max());
  EXPECT_GT(CalculateAngularError(exact, behind, cam_from_world), M_PI / 2);
}

TEST(PoseChecks, PoseDifferences) {
  const Rigid3d a = ExamplePose();
  Rigid3d b = a;
  b.rotation = a.rotation * Eigen::Quaterniond(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitY()));
  EXPECT_NEAR(RotationErrorDegrees(a, b), 0.01 * 180 / M_PI, 1e-10);
  EXPECT_NEAR(RotationErrorDegrees(a, a), 0.0, 1e-12);
  Rigid3d c = a;
  c.translation += a.rotation * Eigen::Vector3d(0.3, 0.0, 0.4);  // centre moves by 0.5
  EXPECT_NEAR(CenterError(a, c), 0.5, 1e-12);
}

TEST(PoseChecks, CheiralityPicksTheTrueRelativePose) {
  Random random(7);
  const Rigid3d cam2_from_cam1(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.1, 1, 0).normalized())),
      Eigen::Vector3d(-1.0, 0.1, 0.05));
  std::vector<Eigen::Vector2d> points1, points2;
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d p(random.UniformReal(-2, 2), random.UniformReal(-2, 2),
                            random.UniformReal(3, 8));
    points1.push_back(p.head<2>() / p.z());
    const Eigen::Vector3d q = cam2_from_cam1 * p;
    points2.push_back(q.head<2>() / q.z());
  }
  std::vector<Eigen::Vector3d> points3D;
  EXPECT_TRUE(CheckCheirality(cam2_from_cam1, points1, points2, &points3D));
  EXPECT_EQ(points3D.size(), 50u);
  // The mirrored translation puts every point behind the cameras.
  Rigid3d flipped = cam2_from_cam1;
  flipped.translation = -flipped.translation;
  EXPECT_FALSE(CheckCheirality(flipped, points1, points2, &points3D));
  EXPECT_TRUE(points3D.empty());
}

}  // namespace
}  // namespace loopsfm
