#include "loopsfm/sfm/self_calibration.h"

#include <cmath>

#include <gtest/gtest.h>

#include "loopsfm/geometry/epipolar.h"
#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

constexpr double kTrueFocal = 800.0;
constexpr int kWidth = 1280, kHeight = 720;

struct Scene {
  MapperInput input;
  std::vector<Rigid3d> cam_from_world;
};

// Frames on an arc around a cloud of points, each looking near (not exactly at) its centre,
// or, with `straight`, walking sideways without turning (focal length not observable).
// Every frame sees every point (keypoint k is point k, with 0.3 px noise); pairs up to 4
// frames apart are uncalibrated with the true F and a wrong relative pose, as verification
// with a wrong focal length would leave them. With a radial term k1, the lens bends the
// points (SIMPLE_RADIAL), the cloud is wider so that they fill the frame, and each pair's F
// is the one fitted to the bent points, as verification fits it.
Scene MakeScene(bool straight, bool prior_focal, double k1 = 0.0) {
  Random random(11);
  Scene scene;
  Camera truth;
  truth.camera_id = 1;
  truth.model_id = CameraModelId::kSimpleRadial;
  truth.width = kWidth;
  truth.height = kHeight;
  truth.params = {kTrueFocal, kWidth / 2.0, kHeight / 2.0, k1};
  Camera camera = prior_focal ? truth : Camera::GuessFromImageSize(kWidth, kHeight);
  camera.camera_id = 1;
  camera.has_prior_focal_length = prior_focal;
  scene.input.cameras = {camera};
  std::vector<Eigen::Vector3d> points;
  const double width = k1 == 0.0 ? 3.0 : 7.0, height = k1 == 0.0 ? 2.0 : 4.0;
  for (int k = 0; k < 300; ++k) {
    points.emplace_back(random.UniformReal(-width, width), random.UniformReal(-height, height),
                        random.UniformReal(-3, 3));
  }
  const int num_frames = 16;
  for (int i = 0; i < num_frames; ++i) {
    Eigen::Matrix3d R;
    Eigen::Vector3d centre;
    if (straight) {
      R = Eigen::Matrix3d::Identity();
      centre = Eigen::Vector3d(0.2 * i, 0, -12);
    } else {
      const double angle = (i * 5.0) * M_PI / 180.0;
      centre = Eigen::Vector3d(12 * std::sin(angle), random.UniformReal(-1, 1), -12 * std::cos(angle));
      // Look at a point near the centre of the cloud: the optical axes do not all meet.
      const Eigen::Vector3d target(random.UniformReal(-2, 2), random.UniformReal(-1, 1),
                                   random.UniformReal(-2, 2));
      const Eigen::Vector3d z = (target - centre).normalized();
      const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
      const Eigen::Vector3d y = z.cross(x);
      R.row(0) = x.transpose();
      R.row(1) = y.transpose();
      R.row(2) = z.transpose();
    }
    scene.cam_from_world.emplace_back(Eigen::Quaterniond(R), -(R * centre));
    MapperFrame frame;
    frame.image_id = static_cast<image_t>(i + 1);
    frame.camera_id = 1;
    frame.name = "frame_" + std::to_string(i);
    for (const Eigen::Vector3d& point : points) {
      frame.points2D.push_back(truth.ImgFromCam(scene.cam_from_world[i] * point) +
                               Eigen::Vector2d(random.Normal(0, 0.3), random.Normal(0, 0.3)));
    }
    scene.input.frames.push_back(std::move(frame));
  }
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  K(0, 0) = K(1, 1) = kTrueFocal;
  K(0, 2) = kWidth / 2.0;
  K(1, 2) = kHeight / 2.0;
  for (int i = 0; i < num_frames; ++i) {
    for (int j = i + 1; j < num_frames && j <= i + 4; ++j) {
      const Rigid3d j_from_i = scene.cam_from_world[j] * scene.cam_from_world[i].Inverse();
      MapperPair pair;
      pair.pair = ImagePair(i + 1, j + 1);
      pair.geometry.config = TwoViewGeometry::kUncalibrated;
      pair.geometry.F = K.transpose().inverse() * Skew(j_from_i.translation) *
                        j_from_i.rotation.toRotationMatrix() * K.inverse();
      if (k1 != 0.0) {
        pair.geometry.F = FundamentalFromEightPoints(scene.input.frames[i].points2D,
                                                     scene.input.frames[j].points2D);
      }
      pair.geometry.cam2_from_cam1 = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d::UnitX());
      for (point2D_t k = 0; k < points.size(); ++k) pair.geometry.inlier_matches.push_back({k, k});
      scene.input.pairs.push_back(std::move(pair));
    }
  }
  return scene;
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / M_PI;
}

TEST(SelfCalibration, EstimatesTheFocalLengthAndReestimatesThePairsPoses) {
  Scene scene = MakeScene(/*straight=*/false, /*prior_focal=*/false);
  const SelfCalibrationReport report = SelfCalibrate({}, &scene.input);
  ASSERT_EQ(report.cameras.size(), 1u);
  const CameraSelfCalibration& c = report.cameras[0];
  EXPECT_TRUE(c.applied) << c.estimate.explanation;
  EXPECT_NEAR(c.initial_focal_px, 1.2 * kWidth, 1e-9);
  EXPECT_NEAR(c.focal_px, kTrueFocal, 0.005 * kTrueFocal);
  const Camera& camera = scene.input.cameras[0];
  EXPECT_DOUBLE_EQ(camera.params[0], c.focal_px);
  EXPECT_FALSE(camera.has_prior_focal_length) << "bundle adjustment must still refine it";
  EXPECT_EQ(report.num_pairs_updated, scene.input.pairs.size());
  for (const MapperPair& pair : scene.input.pairs) {
    const int i = static_cast<int>(pair.pair.image_id1) - 1, j = static_cast<int>(pair.pair.image_id2) - 1;
    const Rigid3d truth = scene.cam_from_world[j] * scene.cam_from_world[i].Inverse();
    const double rotation_error =
        truth.rotation.angularDistance(pair.geometry.cam2_from_cam1.rotation) * 180.0 / M_PI;
    // The wrong pose was 10-20 degrees off; what is left is the polish fitting 0.3 px noise
    // (rotation and translation trade off over short baselines).
    EXPECT_LT(rotation_error, 0.6) << i << "-" << j;
    EXPECT_LT(AngleDeg(truth.translation, pair.geometry.cam2_from_cam1.translation), 3.0) << i << "-" << j;
    EXPECT_EQ(pair.geometry.config, TwoViewGeometry::kUncalibrated);
  }
}

TEST(SelfCalibration, ABarrelLensIsFoundBeforeTheFocalLength) {
  constexpr double kTrueK1 = -0.1;
  Scene scene = MakeScene(/*straight=*/false, /*prior_focal=*/false, kTrueK1);
  const SelfCalibrationReport report = SelfCalibrate({}, &scene.input);
  ASSERT_EQ(report.cameras.size(), 1u);
  const CameraSelfCalibration& c = report.cameras[0];
  ASSERT_TRUE(c.applied) << c.estimate.explanation;
  EXPECT_TRUE(c.distortion_estimated);
  ASSERT_TRUE(c.distortion.significant) << c.distortion.explanation;
  EXPECT_NEAR(c.k1, kTrueK1, 0.01);
  EXPECT_NEAR(c.focal_px, kTrueFocal, 0.01 * kTrueFocal);
  const Camera& camera = scene.input.cameras[0];
  EXPECT_DOUBLE_EQ(camera.params[0], c.focal_px);
  EXPECT_DOUBLE_EQ(camera.params[3], c.k1);

  // Without the distortion step, the same pairs put the focal length off.
  Scene plain = MakeScene(/*straight=*/false, /*prior_focal=*/false, kTrueK1);
  SelfCalibrationOptions no_distortion;
  no_distortion.estimate_distortion = false;
  const CameraSelfCalibration without = SelfCalibrate(no_distortion, &plain.input).cameras.at(0);
  EXPECT_FALSE(without.distortion_estimated);
  EXPECT_EQ(plain.input.cameras[0].params[3], 0.0);
  EXPECT_FALSE(without.applied && std::abs(without.focal_px / kTrueFocal - 1.0) < 0.01)
      << without.focal_px;
}

TEST(SelfCalibration, ALensWithoutDistortionKeepsK1AtZero) {
  Scene scene = MakeScene(/*straight=*/false, /*prior_focal=*/false);
  const CameraSelfCalibration c = SelfCalibrate({}, &scene.input).cameras.at(0);
  EXPECT_TRUE(c.distortion_estimated);
  EXPECT_FALSE(c.distortion.significant);
  EXPECT_EQ(c.k1, 0.0);
  EXPECT_EQ(scene.input.cameras[0].params[3], 0.0);
}

TEST(SelfCalibration, LeavesCamerasWithKnownIntrinsicsAlone) {
  Scene scene = MakeScene(/*straight=*/false, /*prior_focal=*/true);
  const Camera before = scene.input.cameras[0];
  const Rigid3d pose_before = scene.input.pairs[0].geometry.cam2_from_cam1;
  const SelfCalibrationReport report = SelfCalibrate({}, &scene.input);
  EXPECT_TRUE(report.cameras.empty());
  EXPECT_EQ(report.num_pairs_updated, 0u);
  EXPECT_TRUE(scene.input.cameras[0].SameIntrinsics(before));
  EXPECT_TRUE(scene.input.pairs[0].geometry.cam2_from_cam1.translation.isApprox(pose_before.translation));
}

TEST(SelfCalibration, KeepsTheGuessWhenTheVideoNeverTurns) {
  Scene scene = MakeScene(/*straight=*/true, /*prior_focal=*/false);
  const SelfCalibrationReport report = SelfCalibrate({}, &scene.input);
  ASSERT_EQ(report.cameras.size(), 1u);
  EXPECT_FALSE(report.cameras[0].applied);
  EXPECT_FALSE(report.cameras[0].estimate.explanation.empty());
  EXPECT_DOUBLE_EQ(scene.input.cameras[0].params[0], 1.2 * kWidth);
  EXPECT_EQ(report.num_pairs_updated, 0u);
}

}  // namespace
}  // namespace loopsfm
