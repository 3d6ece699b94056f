#include "loopsfm/estimators/absolute_pose.h"

#include <gtest/gtest.h>

#include "loopsfm/geometry/pose_checks.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// A 1280 x 960 camera with a 65 degree field of view (focal length 1000 px).
Camera ExampleCamera(CameraModelId id) {
  Camera camera;
  camera.model_id = id;
  camera.width = 1280;
  camera.height = 960;
  switch (id) {
    case CameraModelId::kSimplePinhole: camera.params = {1000, 640, 480}; break;
    case CameraModelId::kPinhole: camera.params = {1000, 1010, 640, 480}; break;
    case CameraModelId::kSimpleRadial: camera.params = {1000, 640, 480, -0.08}; break;
    case CameraModelId::kRadial: camera.params = {1000, 640, 480, -0.08, 0.01}; break;
    case CameraModelId::kOpenCV:
      camera.params = {1000, 1010, 640, 480, 0.0578, -0.0805, -0.00098, 0.00016};
      break;
    case CameraModelId::kOpenCVFisheye:
      camera.params = {1000, 1010, 640, 480, 0.05, -0.02, 0.004, -0.0008};
      break;
    case CameraModelId::kFullOpenCV:
      camera.params = {1000, 1010, 640, 480, 0.0578, -0.0805,
                       -0.00098, 0.00016, 0.012, 0.03, -0.01, 0.004};
      break;
    case CameraModelId::kSimpleRadialFisheye: camera.params = {1000, 640, 480, 0.03}; break;
    case CameraModelId::kRadialFisheye: camera.params = {1000, 640, 480, 0.03, -0.005}; break;
  }
  camera.Check();
  return camera;
}

// Points 5..15 units in front of a random pose (scene size about 10), seen at random
// pixels with Gaussian pixel noise; the first outlier_ratio of them get random pixels.
struct Scene {
  Rigid3d cam_from_world;
  std::vector<Eigen::Vector2d> points2D;
  std::vector<Eigen::Vector3d> points3D;
  std::vector<bool> is_inlier;
};

Scene MakeScene(Random& random, const Camera& camera, int n, double outlier_ratio,
                double noise_px) {
  Scene scene;
  const Eigen::Vector3d axis =
      Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
  scene.cam_from_world =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(random.UniformReal(0, 3), axis)),
              Eigen::Vector3d(random.Normal(0, 5), random.Normal(0, 5), random.Normal(0, 5)));
  const Rigid3d world_from_cam = scene.cam_from_world.Inverse();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d pixel(random.UniformReal(0, camera.width),
                                random.UniformReal(0, camera.height));
    const double depth = random.UniformReal(5, 15);
    scene.points3D.push_back(world_from_cam * (depth * camera.CamFromImg(pixel).homogeneous()));
    const bool outlier = i < outlier_ratio * n;
    scene.is_inlier.push_back(!outlier);
    scene.points2D.push_back(
        outlier ? Eigen::Vector2d(random.UniformReal(0, camera.width),
                                  random.UniformReal(0, camera.height))
                : pixel + Eigen::Vector2d(random.Normal(0, noise_px), random.Normal(0, noise_px)));
  }
  return scene;
}

Rigid3d Perturb(const Rigid3d& pose, double angle_rad, const Eigen::Vector3d& delta_t) {
  Rigid3d perturbed = pose;
  perturbed.rotation =
      (Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, Eigen::Vector3d(1, -1, 2).normalized())) *
       pose.rotation)
          .normalized();
  perturbed.translation += delta_t;
  return perturbed;
}

class AbsolutePoseTest : public ::testing::TestWithParam<CameraModelId> {};

TEST_P(AbsolutePoseTest, IsAccurateWith40PercentOutliersAnd1PxNoise) {
  const Camera camera = ExampleCamera(GetParam());
  AbsolutePoseEstimationOptions options;
  options.max_error_px = 4.0;
  double max_rotation_error = 0.0, max_center_error = 0.0;
  double sum_rotation_error = 0.0, sum_reference_error = 0.0;
  for (int seed = 0; seed < 10; ++seed) {
    Random data_random(500 + seed);
    const Scene scene = MakeScene(data_random, camera, 200, 0.4, 1.0);
    Random random(seed);
    const AbsolutePoseReport report =
        EstimateAbsolutePose(scene.points2D, scene.points3D, camera, options, random);
    ASSERT_TRUE(report.success);
    const double rotation_error = RotationErrorDegrees(report.cam_from_world, scene.cam_from_world);
    max_rotation_error = std::max(max_rotation_error, rotation_error);
    // The noise-limited reference: least squares on the true inliers, from the truth.
    Rigid3d reference = scene.cam_from_world;
    Camera camera_copy = camera;
    AbsolutePoseRefinementOptions least_squares;
    least_squares.loss_type = RobustLossType::kTrivial;
    const std::vector<char> true_mask(scene.is_inlier.begin(), scene.is_inlier.end());
    ASSERT_TRUE(RefineAbsolutePose(least_squares, true_mask, scene.points2D, scene.points3D,
                                   &reference, &camera_copy)
                    .success);
    sum_rotation_error += rotation_error;
    sum_reference_error += RotationErrorDegrees(reference, scene.cam_from_world);
    max_center_error =
        std::max(max_center_error, CenterError(report.cam_from_world, scene.cam_from_world));
    int missed = 0, wrong = 0;
    for (size_t i = 0; i < scene.is_inlier.size(); ++i) {
      missed += scene.is_inlier[i] && !report.inlier_mask[i];
      wrong += !scene.is_inlier[i] && report.inlier_mask[i];
    }
    EXPECT_LE(missed, 2);
    EXPECT_LE(wrong, 5);
    EXPECT_EQ(report.num_inliers,
              std::count(report.inlier_mask.begin(), report.inlier_mask.end(), 1));
  }
  RecordProperty("max_rotation_error_deg", std::to_string(max_rotation_error));
  RecordProperty("max_center_error", std::to_string(max_center_error));
  EXPECT_LT(max_rotation_error, 0.1);
  EXPECT_LT(max_center_error, 0.01 * 10.0);  // 1% of the scene size
  // Close to the noise limit (the robust loss costs a little efficiency).
  EXPECT_LT(sum_rotation_error, 1.5 * sum_reference_error);
}

INSTANTIATE_TEST_SUITE_P(AllModels, AbsolutePoseTest, ::testing::ValuesIn(kCameraModelIds));

TEST(AbsolutePose, IsDeterministicForASeed) {
  const Camera camera = ExampleCamera(CameraModelId::kSimpleRadial);
  Random data_random(600);
  const Scene scene = MakeScene(data_random, camera, 120, 0.5, 1.0);
  const AbsolutePoseEstimationOptions options;
  Random a(3), b(3);
  const auto report_a = EstimateAbsolutePose(scene.points2D, scene.points3D, camera, options, a);
  const auto report_b = EstimateAbsolutePose(scene.points2D, scene.points3D, camera, options, b);
  ASSERT_TRUE(report_a.success);
  EXPECT_EQ(report_a.num_trials, report_b.num_trials);
  EXPECT_EQ(report_a.inlier_mask, report_b.inlier_mask);
  EXPECT_EQ(report_a.cam_from_world.rotation.coeffs(), report_b.cam_from_world.rotation.coeffs());
  EXPECT_EQ(report_a.cam_from_world.translation, report_b.cam_from_world.translation);
}

TEST(AbsolutePose, FailsWithTooFewCorrespondences) {
  const Camera camera = ExampleCamera(CameraModelId::kPinhole);
  Random data_random(601);
  const Scene scene = MakeScene(data_random, camera, 5, 0.0, 0.0);
  Random random(1);
  const AbsolutePoseEstimationOptions options;  // min_num_inliers = 6
  EXPECT_FALSE(EstimateAbsolutePose(scene.points2D, scene.points3D, camera, options, random).success);
  const std::vector<Eigen::Vector2d> none2D;
  const std::vector<Eigen::Vector3d> none3D;
  EXPECT_FALSE(EstimateAbsolutePose(none2D, none3D, camera, options, random).success);
}

TEST(AbsolutePose, RefinementImprovesAPerturbedPose) {
  const Camera camera = ExampleCamera(CameraModelId::kOpenCV);
  Random data_random(602);
  const Scene scene = MakeScene(data_random, camera, 150, 0.0, 1.0);
  Rigid3d pose = Perturb(scene.cam_from_world, 0.02, Eigen::Vector3d(0.2, -0.1, 0.3));
  const double rotation_error_before = RotationErrorDegrees(pose, scene.cam_from_world);
  const double center_error_before = CenterError(pose, scene.cam_from_world);
  Camera camera_copy = camera;
  const AbsolutePoseRefinementReport report = RefineAbsolutePose(
      AbsolutePoseRefinementOptions(), {}, scene.points2D, scene.points3D, &pose, &camera_copy);
  ASSERT_TRUE(report.success);
  EXPECT_EQ(report.num_residuals, 150);
  EXPECT_GT(report.initial_rmse_px, 10.0);
  EXPECT_LT(report.final_rmse_px, 1.6);  // about sqrt(2) px of noise
  EXPECT_LT(RotationErrorDegrees(pose, scene.cam_from_world), 0.05 * rotation_error_before);
  EXPECT_LT(CenterError(pose, scene.cam_from_world), 0.05 * center_error_before);
  EXPECT_EQ(camera_copy.params, camera.params);  // intrinsics untouched by default
}

TEST(AbsolutePose, RobustLossIgnoresOutliersInRefinement) {
  const Camera camera = ExampleCamera(CameraModelId::kPinhole);
  Random data_random(603);
  const Scene scene = MakeScene(data_random, camera, 200, 0.15, 0.5);
  double errors[2];
  for (int robust = 0; robust < 2; ++robust) {
    Rigid3d pose = Perturb(scene.cam_from_world, 0.005, Eigen::Vector3d(0.05, 0.0, -0.05));
    Camera camera_copy = camera;
    AbsolutePoseRefinementOptions options;
    options.loss_type = robust ? RobustLossType::kCauchy : RobustLossType::kTrivial;
    ASSERT_TRUE(RefineAbsolutePose(options, {}, scene.points2D, scene.points3D, &pose,
                                   &camera_copy)
                    .success);
    errors[robust] = RotationErrorDegrees(pose, scene.cam_from_world);
  }
  EXPECT_LT(errors[1], 0.02);
  EXPECT_LT(errors[1], 0.5 * errors[0]);
}

TEST(AbsolutePose, RefinementRecoversTheFocalLengthWhenAsked) {
  const Camera truth = ExampleCamera(CameraModelId::kSimpleRadial);
  Random data_random(604);
  const Scene scene = MakeScene(data_random, truth, 300, 0.0, 0.5);
  Camera camera = truth;
  camera.params[0] *= 1.05;
  Rigid3d pose = Perturb(scene.cam_from_world, 0.002, Eigen::Vector3d(0.02, 0.0, 0.0));
  AbsolutePoseRefinementOptions options;
  options.refine_focal_length = true;
  options.refine_extra_params = true;
  const auto report =
      RefineAbsolutePose(options, {}, scene.points2D, scene.points3D, &pose, &camera);
  ASSERT_TRUE(report.success);
  EXPECT_NEAR(camera.params[0], truth.params[0], 0.005 * truth.params[0]);
  EXPECT_NEAR(camera.params[3], truth.params[3], 0.01);
  // The principal point is never refined.
  EXPECT_EQ(camera.params[1], truth.params[1]);
  EXPECT_EQ(camera.params[2], truth.params[2]);
  EXPECT_LT(RotationErrorDegrees(pose, scene.cam_from_world), 0.05);
}

TEST(AbsolutePose, RefinementNeedsEnoughInliers) {
  const Camera camera = ExampleCamera(CameraModelId::kPinhole);
  Random data_random(605);
  const Scene scene = MakeScene(data_random, camera, 10, 0.0, 0.0);
  std::vector<char> mask(10, 0);
  mask[0] = mask[1] = 1;
  Rigid3d pose = Perturb(scene.cam_from_world, 0.01, Eigen::Vector3d::Zero());
  const Rigid3d before = pose;
  Camera camera_copy = camera;
  EXPECT_FALSE(RefineAbsolutePose(AbsolutePoseRefinementOptions(), mask, scene.points2D,
                                  scene.points3D, &pose, &camera_copy)
                   .success);
  EXPECT_EQ(pose.rotation.coeffs(), before.rotation.coeffs());
}

TEST(AbsolutePose, OptionsAreChecked) {
  AbsolutePoseEstimationOptions options;
  options.Check();
  options.max_error_px = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = AbsolutePoseEstimationOptions();
  options.ransac.confidence = 2;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = AbsolutePoseEstimationOptions();
  options.refinement.loss_scale_px = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
