#include "loopsfm/matching/geometric_verification.h"

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "loopsfm/matching/relative_pose_refinement.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

enum class SceneKind { kGeneral, kPlanar, kRotation };

// Two views of random points with a known cam2_from_cam1; matches in shuffled order, with
// keypoints2 stored in a different order than keypoints1, plus random outlier matches.
struct TwoViewScene {
  Camera camera1, camera2;
  FeatureKeypoints keypoints1, keypoints2;
  FeatureMatches matches;
  std::vector<bool> is_true;  // per match
  Rigid3d cam2_from_cam1;
  int num_true = 0;
};

Camera PinholeCamera(bool known_focal) {
  Camera camera;
  camera.model_id = CameraModelId::kPinhole;
  camera.width = 640;
  camera.height = 480;
  camera.params = {600, 600, 320, 240};
  camera.has_prior_focal_length = known_focal;
  return camera;
}

Camera RadialCamera() {
  Camera camera;
  camera.model_id = CameraModelId::kSimpleRadial;
  camera.width = 640;
  camera.height = 480;
  camera.params = {550, 320, 240, -0.08};
  camera.has_prior_focal_length = true;
  return camera;
}

TwoViewScene MakeScene(SceneKind kind, const Camera& camera, int num_true, int num_outliers,
                       double noise_px, Random& random) {
  TwoViewScene scene;
  scene.camera1 = scene.camera2 = camera;
  const Eigen::Quaterniond rotation(
      Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d(0.1, 1.0, 0.05).normalized()));
  const Eigen::Vector3d center2_in_cam1 =
      kind == SceneKind::kRotation ? Eigen::Vector3d::Zero() : Eigen::Vector3d(1.0, 0.1, 0.2);
  scene.cam2_from_cam1 = Rigid3d(rotation, -(rotation * center2_in_cam1));
  const Eigen::Vector3d plane_normal = Eigen::Vector3d(0.2, -0.1, 1.0).normalized();

  std::vector<Eigen::Vector2d> points1, points2;
  while (static_cast<int>(points1.size()) < num_true) {
    const Eigen::Vector2d pixel1(random.UniformReal(0, camera.width),
                                 random.UniformReal(0, camera.height));
    const Eigen::Vector3d ray = camera.CamFromImg(pixel1).homogeneous();
    const double depth = kind == SceneKind::kPlanar ? 6.0 / plane_normal.dot(ray)
                                                    : random.UniformReal(4.0, 8.0);
    const Eigen::Vector3d point_in_cam2 = scene.cam2_from_cam1 * (depth * ray);
    if (point_in_cam2.z() < 0.5) continue;
    const Eigen::Vector2d pixel2 = camera.ImgFromCam(point_in_cam2);
    if (pixel2.x() < 0 || pixel2.y() < 0 || pixel2.x() > camera.width ||
        pixel2.y() > camera.height) {
      continue;
    }
    points1.push_back(pixel1 + noise_px * Eigen::Vector2d(random.Normal(), random.Normal()));
    points2.push_back(pixel2 + noise_px * Eigen::Vector2d(random.Normal(), random.Normal()));
  }
  for (int i = 0; i < num_outliers; ++i) {
    points1.emplace_back(random.UniformReal(0, camera.width), random.UniformReal(0, camera.height));
    points2.emplace_back(random.UniformReal(0, camera.width), random.UniformReal(0, camera.height));
  }
  const uint32_t n = static_cast<uint32_t>(points1.size());
  const std::vector<uint32_t> slot2 = random.Sample(n, n);
  const std::vector<uint32_t> match_order = random.Sample(n, n);
  scene.keypoints1.resize(n);
  scene.keypoints2.resize(n);
  for (uint32_t i = 0; i < n; ++i) {
    scene.keypoints1[i] = {static_cast<float>(points1[i].x()), static_cast<float>(points1[i].y())};
    scene.keypoints2[slot2[i]] = {static_cast<float>(points2[i].x()),
                                  static_cast<float>(points2[i].y())};
  }
  for (const uint32_t i : match_order) {
    scene.matches.push_back({i, slot2[i]});
    scene.is_true.push_back(static_cast<int>(i) < num_true);
  }
  scene.num_true = num_true;
  return scene;
}

TwoViewVerification Verify(const TwoViewScene& scene, uint64_t seed = 1,
                           const TwoViewVerificationOptions& options = {}) {
  Random random(seed);
  return VerifyTwoViewGeometry(scene.camera1, scene.keypoints1, scene.camera2, scene.keypoints2,
                               scene.matches, options, random);
}

// Fraction of the true matches among the inliers, and number of outliers among them.
std::pair<double, int> InlierQuality(const TwoViewScene& scene, const TwoViewGeometry& geometry) {
  std::vector<bool> is_true_by_idx1(scene.keypoints1.size(), false);
  for (size_t k = 0; k < scene.matches.size(); ++k) {
    is_true_by_idx1[scene.matches[k].point2D_idx1] = scene.is_true[k];
  }
  int true_found = 0, false_found = 0;
  for (const FeatureMatch& m : geometry.inlier_matches) {
    (is_true_by_idx1[m.point2D_idx1] ? true_found : false_found)++;
  }
  return {static_cast<double>(true_found) / scene.num_true, false_found};
}

// Largest Sampson error, in pixels, of the inliers under the true relative pose.
double MaxTrueEpipolarErrorPx(const TwoViewScene& scene, const TwoViewGeometry& geometry) {
  const Eigen::Matrix3d E = EssentialFromPose(scene.cam2_from_cam1);
  double max_error = 0;
  for (const FeatureMatch& m : geometry.inlier_matches) {
    const FeatureKeypoint& k1 = scene.keypoints1[m.point2D_idx1];
    const FeatureKeypoint& k2 = scene.keypoints2[m.point2D_idx2];
    const double error = std::sqrt(SampsonSquaredError(
        E, scene.camera1.CamFromImg(Eigen::Vector2d(k1.x, k1.y)),
        scene.camera2.CamFromImg(Eigen::Vector2d(k2.x, k2.y))));
    max_error = std::max(max_error, error * scene.camera1.MeanFocalLength());
  }
  return max_error;
}

double RotationErrorDeg(const Rigid3d& estimate, const Rigid3d& truth) {
  return RotationAngleDegrees(estimate.rotation * truth.rotation.inverse());
}

double TranslationDirectionErrorDeg(const Rigid3d& estimate, const Rigid3d& truth) {
  const double c = estimate.translation.normalized().dot(truth.translation.normalized());
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / M_PI;
}

TEST(VerifyTwoViewGeometry, CalibratedPairWithOutliers) {
  for (const Camera& camera : {PinholeCamera(true), RadialCamera()}) for (int seed = 0; seed < 10; ++seed) {
    Random random(21 + seed);
    const TwoViewScene scene = MakeScene(SceneKind::kGeneral, camera, 350, 150, 0.7, random);
    const TwoViewVerification result = Verify(scene);
    const TwoViewGeometry& g = result.geometry;
    SCOPED_TRACE(camera.ModelName() + " seed " + std::to_string(seed));
    ASSERT_EQ(g.config, TwoViewGeometry::kCalibrated);
    EXPECT_TRUE(g.IsVerified());
    const auto [recall, num_false] = InlierQuality(scene, g);
    EXPECT_GT(recall, 0.95);
    // Outliers that happen to lie near their epipolar line cannot be told apart; there are few
    // and they fit the true geometry.
    EXPECT_LE(num_false, 0.1 * 150);
    EXPECT_LT(MaxTrueEpipolarErrorPx(scene, g), 1.5 * TwoViewVerificationOptions().max_error);
    EXPECT_LT(RotationErrorDeg(g.cam2_from_cam1, scene.cam2_from_cam1), 0.5);
    EXPECT_LT(TranslationDirectionErrorDeg(g.cam2_from_cam1, scene.cam2_from_cam1), 2.0);
    EXPECT_NEAR(g.cam2_from_cam1.translation.norm(), 1.0, 1e-9);
    EXPECT_GT(result.num_pose_inliers, 0.95 * g.inlier_matches.size());
    EXPECT_LT(result.h_inlier_ratio, 0.8);
    // Rays meet at roughly baseline / depth = 1 / 6 rad.
    EXPECT_GT(result.median_tri_angle_deg, 5.0);
    EXPECT_LT(result.median_tri_angle_deg, 20.0);
    EXPECT_EQ(result.num_matches, 500);
    // x2^T E x1 = 0 on normalised coordinates of a true match.
    const FeatureMatch& m = scene.matches[std::find(scene.is_true.begin(), scene.is_true.end(),
                                                    true) - scene.is_true.begin()];
    const FeatureKeypoint& k1 = scene.keypoints1[m.point2D_idx1];
    const FeatureKeypoint& k2 = scene.keypoints2[m.point2D_idx2];
    const Eigen::Vector3d x1 = camera.CamFromImg(Eigen::Vector2d(k1.x, k1.y)).homogeneous();
    const Eigen::Vector3d x2 = camera.CamFromImg(Eigen::Vector2d(k2.x, k2.y)).homogeneous();
    EXPECT_LT(std::abs(x2.dot(g.E.normalized() * x1)), 1e-2);
  }
}

TEST(VerifyTwoViewGeometry, UncalibratedPairUsesTheFundamentalMatrix) {
  for (int seed = 0; seed < 10; ++seed) {
  Random random(40 + seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const TwoViewScene scene =
      MakeScene(SceneKind::kGeneral, PinholeCamera(false), 350, 150, 0.7, random);
  const TwoViewVerification result = Verify(scene);
  const TwoViewGeometry& g = result.geometry;
  ASSERT_EQ(g.config, TwoViewGeometry::kUncalibrated);
  EXPECT_EQ(result.num_E_inliers, 0);
  const auto [recall, num_false] = InlierQuality(scene, g);
  EXPECT_GT(recall, 0.95);
  // F (7 degrees of freedom) admits a few more outliers far along their epipolar lines than E.
  EXPECT_LE(num_false, 0.1 * 150);
  // The (here correct) guessed intrinsics turn F into a relative pose, polished on F's inliers.
  EXPECT_LT(RotationErrorDeg(g.cam2_from_cam1, scene.cam2_from_cam1), 0.5);
  EXPECT_LT(TranslationDirectionErrorDeg(g.cam2_from_cam1, scene.cam2_from_cam1), 2.0);
  }
}

TEST(VerifyTwoViewGeometry, PlanarSceneIsPlanar) {
  Random random(23);
  const TwoViewScene scene =
      MakeScene(SceneKind::kPlanar, PinholeCamera(true), 300, 100, 0.5, random);
  const TwoViewVerification result = Verify(scene);
  const TwoViewGeometry& g = result.geometry;
  ASSERT_EQ(g.config, TwoViewGeometry::kPlanar);
  EXPECT_GT(result.h_inlier_ratio, 0.8);
  EXPECT_GT(InlierQuality(scene, g).first, 0.95);
  EXPECT_NEAR(g.cam2_from_cam1.translation.norm(), 1.0, 1e-9);
  EXPECT_LT(RotationErrorDeg(g.cam2_from_cam1, scene.cam2_from_cam1), 1.0);
  EXPECT_LT(TranslationDirectionErrorDeg(g.cam2_from_cam1, scene.cam2_from_cam1), 5.0);
}

TEST(VerifyTwoViewGeometry, PureRotationIsPanoramic) {
  Random random(24);
  const TwoViewScene scene =
      MakeScene(SceneKind::kRotation, PinholeCamera(true), 300, 100, 0.5, random);
  const TwoViewVerification result = Verify(scene);
  const TwoViewGeometry& g = result.geometry;
  ASSERT_EQ(g.config, TwoViewGeometry::kPanoramic);
  EXPECT_GT(result.h_inlier_ratio, 0.8);
  EXPECT_GT(InlierQuality(scene, g).first, 0.95);
  EXPECT_EQ(g.cam2_from_cam1.translation, Eigen::Vector3d::Zero());
  EXPECT_LT(RotationErrorDeg(g.cam2_from_cam1, scene.cam2_from_cam1), 0.5);
  EXPECT_LT(result.median_tri_angle_deg, 0.5);
}

TEST(VerifyTwoViewGeometry, TooFewMatchesAreRejected) {
  Random random(25);
  const TwoViewScene few = MakeScene(SceneKind::kGeneral, PinholeCamera(true), 10, 0, 0.5, random);
  TwoViewVerification result = Verify(few);
  EXPECT_EQ(result.geometry.config, TwoViewGeometry::kDegenerate);
  EXPECT_TRUE(result.geometry.inlier_matches.empty());
  EXPECT_FALSE(result.geometry.IsVerified());

  // 12 consistent matches among 300 random ones: below min_num_inliers = 15.
  const TwoViewScene noise =
      MakeScene(SceneKind::kGeneral, PinholeCamera(true), 12, 300, 0.5, random);
  result = Verify(noise);
  EXPECT_EQ(result.geometry.config, TwoViewGeometry::kDegenerate);
  EXPECT_TRUE(result.geometry.inlier_matches.empty());
}

TEST(VerifyTwoViewGeometry, InlierRatioBelowMinimumIsRejected) {
  Random random(26);
  const TwoViewScene scene =
      MakeScene(SceneKind::kGeneral, PinholeCamera(true), 60, 440, 0.5, random);
  TwoViewVerificationOptions options;
  EXPECT_TRUE(Verify(scene, 1, options).geometry.IsVerified());  // 12% >= 10%
  options.min_inlier_ratio = 0.2;
  EXPECT_FALSE(Verify(scene, 1, options).geometry.IsVerified());
}

TEST(VerifyTwoViewGeometry, DeterministicForASeedWhateverTheThreads) {
  Random random(27);
  std::vector<TwoViewScene> scenes;
  for (int k = 0; k < 6; ++k) {
    scenes.push_back(MakeScene(SceneKind::kGeneral, PinholeCamera(k % 2 == 0), 200, 200, 1.0,
                               random));
  }
  std::vector<TwoViewVerification> serial, parallel(scenes.size());
  for (size_t k = 0; k < scenes.size(); ++k) serial.push_back(Verify(scenes[k], 100 + k));
  tbb::parallel_for(size_t{0}, scenes.size(),
                    [&](size_t k) { parallel[k] = Verify(scenes[k], 100 + k); });
  for (size_t k = 0; k < scenes.size(); ++k) {
    EXPECT_EQ(parallel[k].geometry.inlier_matches, serial[k].geometry.inlier_matches);
    EXPECT_EQ(parallel[k].geometry.config, serial[k].geometry.config);
    EXPECT_EQ(parallel[k].num_H_inliers, serial[k].num_H_inliers);
    EXPECT_TRUE(parallel[k].geometry.cam2_from_cam1.rotation.isApprox(
        serial[k].geometry.cam2_from_cam1.rotation, 0.0));
  }
}

TEST(VerifyTwoViewGeometry, RejectsBadInput) {
  Random random(28);
  TwoViewScene scene = MakeScene(SceneKind::kGeneral, PinholeCamera(true), 50, 0, 0.5, random);
  scene.matches.push_back({0, static_cast<point2D_t>(scene.keypoints2.size())});
  EXPECT_THROW(Verify(scene), InputError);
  TwoViewVerificationOptions options;
  options.min_num_inliers = 5;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options.min_num_inliers = 15;
  options.confidence = 1.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
