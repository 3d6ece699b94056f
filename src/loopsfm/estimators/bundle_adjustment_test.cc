#include "loopsfm/estimators/bundle_adjustment.h"

#include <cmath>
#include <memory>
#include <set>
#include <string>
#include <unordered_set>
#include <vector>

#include <gtest/gtest.h>

#include "loopsfm/estimators/cost_functions/focal_prior.h"
#include "loopsfm/estimators/cost_functions/point_distance.h"
#include "loopsfm/estimators/cost_functions/relative_pose.h"
#include "loopsfm/estimators/cost_functions/reprojection_error.h"
#include "loopsfm/geometry/umeyama.h"
#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

constexpr int kWidth = 640;
constexpr int kHeight = 480;

Camera MakeCamera(CameraModelId model_id, double focal) {
  Camera camera;
  camera.camera_id = 1;
  camera.model_id = model_id;
  camera.width = kWidth;
  camera.height = kHeight;
  switch (model_id) {
    case CameraModelId::kPinhole: camera.params = {focal, focal * 1.01, 322.0, 238.0}; break;
    case CameraModelId::kSimpleRadial: camera.params = {focal, 322.0, 238.0, -0.06}; break;
    case CameraModelId::kRadial: camera.params = {focal, 322.0, 238.0, -0.06, 0.01}; break;
    case CameraModelId::kOpenCV:
      camera.params = {focal, focal * 1.01, 322.0, 238.0, -0.06, 0.01, 0.001, -0.002};
      break;
    case CameraModelId::kOpenCVFisheye:
      camera.params = {focal, focal * 1.01, 322.0, 238.0, 0.05, -0.02, 0.004, -0.0008};
      break;
    case CameraModelId::kFullOpenCV:
      camera.params = {focal, focal * 1.01, 322.0, 238.0, -0.06, 0.01,
                       0.001, -0.002, 0.003, 0.02, -0.01, 0.004};
      break;
    case CameraModelId::kSimpleRadialFisheye: camera.params = {focal, 322.0, 238.0, 0.03}; break;
    case CameraModelId::kRadialFisheye:
      camera.params = {focal, 322.0, 238.0, 0.03, -0.005};
      break;
    default: camera.params = {focal, 320.0, 240.0}; camera.model_id = CameraModelId::kSimplePinhole;
  }
  return camera;
}

// cam_from_world of a camera at `centre` looking at `target` with world +y roughly up.
Rigid3d LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitY()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_from_cam;
  world_from_cam << x, y, z;
  const Eigen::Quaterniond rotation(world_from_cam.transpose());
  return Rigid3d(rotation, -(rotation * centre));
}

// Adds images with the given poses, then points seen by at least two of them, with exact
// observations.
Reconstruction ObserveScene(const Camera& camera, const std::vector<Rigid3d>& poses,
                            const std::vector<Eigen::Vector3d>& points) {
  std::vector<Image> images(poses.size());
  std::vector<Track> tracks(points.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    images[i].image_id = static_cast<image_t>(i + 1);
    images[i].camera_id = camera.camera_id;
    images[i].cam_from_world = poses[i];
    images[i].registered = true;
    for (size_t p = 0; p < points.size(); ++p) {
      const Eigen::Vector3d in_cam = poses[i] * points[p];
      if (in_cam.z() < 0.5) continue;
      const Eigen::Vector2d xy = camera.ImgFromCam(in_cam);
      if (xy.x() < 0 || xy.y() < 0 || xy.x() > kWidth || xy.y() > kHeight) continue;
      tracks[p].elements.push_back(
          {images[i].image_id, static_cast<point2D_t>(images[i].points2D.size())});
      images[i].points2D.push_back({xy, kInvalidPoint3DId});
    }
  }
  Reconstruction reconstruction;
  reconstruction.AddCamera(camera);
  for (Image& image : images) reconstruction.AddImage(std::move(image));
  for (size_t p = 0; p < points.size(); ++p) {
    if (tracks[p].Length() >= 2) reconstruction.AddPoint3D(points[p], tracks[p]);
  }
  return reconstruction;
}

// Cameras on an arc of radius 6 around a box of points at the origin (scene size ~12).
Reconstruction MakeArcScene(CameraModelId model_id, int num_images, int num_points, uint64_t seed) {
  Random random(seed);
  std::vector<Rigid3d> poses;
  for (int i = 0; i < num_images; ++i) {
    const double angle = (-60.0 + 120.0 * i / (num_images - 1)) * M_PI / 180.0;
    const Eigen::Vector3d centre(6.0 * std::sin(angle), 0.5 * std::sin(3 * angle),
                                 -6.0 * std::cos(angle));
    poses.push_back(LookAt(centre, Eigen::Vector3d(0.0, 0.1 * std::cos(angle), 0.0)));
  }
  std::vector<Eigen::Vector3d> points;
  for (int p = 0; p < num_points; ++p) {
    points.emplace_back(random.UniformReal(-2, 2), random.UniformReal(-1.5, 1.5),
                        random.UniformReal(-2, 2));
  }
  return ObserveScene(MakeCamera(model_id, 400.0), poses, points);
}

Eigen::Quaterniond SmallRotation(Random& random, double degrees) {
  const Eigen::Vector3d axis =
      Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
  return Eigen::Quaterniond(Eigen::AngleAxisd(degrees * M_PI / 180.0, axis));
}

// Rotates each pose by ~`degrees` and moves its centre by ~`centre_noise` (except the
// images in `keep`), and moves every point by ~`point_noise`.
void Perturb(Reconstruction* reconstruction, const std::set<image_t>& keep, double degrees,
             double centre_noise, double point_noise, uint64_t seed) {
  Random random(seed);
  for (const image_t id : reconstruction->RegImageIds()) {
    if (keep.count(id)) continue;
    Image& image = reconstruction->GetImage(id);
    const Eigen::Vector3d centre =
        image.ProjectionCenter() +
        centre_noise * Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal());
    image.cam_from_world.rotation =
        (SmallRotation(random, degrees) * image.cam_from_world.rotation).normalized();
    image.cam_from_world.translation = -(image.cam_from_world.rotation * centre);
  }
  for (auto& [id, point] : reconstruction->Points3D()) {
    point.xyz += point_noise * Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal());
  }
}

// Gaussian noise of `sigma` pixels on every observation.
void AddPixelNoise(Reconstruction* reconstruction, double sigma, uint64_t seed) {
  Random random(seed);
  for (const image_t id : reconstruction->RegImageIds()) {
    for (Point2D& point2D : reconstruction->GetImage(id).points2D) {
      point2D.xy += sigma * Eigen::Vector2d(random.Normal(), random.Normal());
    }
  }
}

struct PoseErrors {
  double max_rotation_deg = 0.0;
  double max_centre = 0.0;
};

PoseErrors ComparePoses(const Reconstruction& truth, const Reconstruction& estimate) {
  PoseErrors errors;
  for (const image_t id : truth.RegImageIds()) {
    const Image& a = truth.GetImage(id);
    const Image& b = estimate.GetImage(id);
    errors.max_rotation_deg = std::max(
        errors.max_rotation_deg,
        RotationAngleDegrees(a.cam_from_world.rotation * b.cam_from_world.rotation.inverse()));
    errors.max_centre =
        std::max(errors.max_centre, (a.ProjectionCenter() - b.ProjectionCenter()).norm());
  }
  return errors;
}

// The estimate moved by the similarity that best maps its camera centres onto the truth's.
Reconstruction AlignedToTruth(const Reconstruction& truth, const Reconstruction& estimate) {
  const std::vector<image_t> ids = truth.RegImageIds();
  Eigen::Matrix3Xd from(3, ids.size()), to(3, ids.size());
  for (size_t i = 0; i < ids.size(); ++i) {
    from.col(i) = estimate.GetImage(ids[i]).ProjectionCenter();
    to.col(i) = truth.GetImage(ids[i]).ProjectionCenter();
  }
  const Eigen::Matrix4d transform = Eigen::umeyama(from, to, /*with_scaling=*/true);
  Sim3d truth_from_estimate;
  truth_from_estimate.scale = transform.block<3, 1>(0, 0).norm();
  truth_from_estimate.rotation =
      Eigen::Quaterniond(transform.block<3, 3>(0, 0) / truth_from_estimate.scale);
  truth_from_estimate.translation = transform.block<3, 1>(0, 3);
  Reconstruction aligned = estimate;
  aligned.Transform(truth_from_estimate);
  return aligned;
}

double MeanReprojectionError(const Reconstruction& reconstruction) {
  double sum = 0.0;
  int count = 0;
  for (const auto& [id, point] : reconstruction.Points3D()) {
    for (const TrackElement& element : point.track.elements) {
      sum += reconstruction.ReprojectionError(point, element).value_or(1e9);
      ++count;
    }
  }
  return sum / count;
}

BundleAdjustmentConfig AllImagesConfig(const Reconstruction& reconstruction) {
  BundleAdjustmentConfig config;
  for (const image_t id : reconstruction.RegImageIds()) config.AddImage(id);
  return config;
}

// Full config with the gauge fixed through images 1 and 2.
BundleAdjustmentConfig GaugeFixedConfig(const Reconstruction& truth) {
  BundleAdjustmentConfig config = AllImagesConfig(truth);
  FixGaugeWithTwoImages(truth, 1, 2, &config);
  return config;
}

// Perturbs the second gauge image everywhere except its held centre coordinate.
void PerturbSecondGaugeImage(Reconstruction* reconstruction, int held_coord) {
  Random random(99);
  Image& image = reconstruction->GetImage(2);
  Eigen::Vector3d centre = image.ProjectionCenter();
  for (int c = 0; c < 3; ++c) {
    if (c != held_coord) centre[c] += 0.03;
  }
  image.cam_from_world.rotation =
      (SmallRotation(random, 0.7) * image.cam_from_world.rotation).normalized();
  image.cam_from_world.translation = -(image.cam_from_world.rotation * centre);
}

class BundleAdjustmentModelTest : public ::testing::TestWithParam<CameraModelId> {};

TEST_P(BundleAdjustmentModelTest, NoiselessSceneIsRecoveredExactly) {
  const Reconstruction truth = MakeArcScene(GetParam(), 12, 400, 1);
  const BundleAdjustmentConfig config = GaugeFixedConfig(truth);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1, 2}, 0.8, 0.03, 0.03, 2);
  PerturbSecondGaugeImage(&reconstruction, config.ConstantCentreCoords(2)->front());
  ASSERT_GT(MeanReprojectionError(reconstruction), 1.0);

  BundleAdjuster adjuster(BundleAdjustmentOptions::Global(), config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  const BundleAdjustmentReport& report = adjuster.report();
  EXPECT_EQ(report.linear_solver, "DENSE_SCHUR");
  EXPECT_EQ(report.num_variable_images, 11);
  EXPECT_EQ(report.num_variable_points, static_cast<int>(truth.NumPoints3D()));
  EXPECT_EQ(report.num_variable_cameras, 0);
  EXPECT_EQ(report.num_reprojection_residual_blocks,
            static_cast<int>(truth.ComputeNumObservations()));
  EXPECT_LT(report.final_cost, 1e-12 * report.initial_cost);

  const PoseErrors errors = ComparePoses(truth, reconstruction);
  EXPECT_LT(errors.max_rotation_deg, 1e-6);
  EXPECT_LT(errors.max_centre, 1e-7);  // scene size ~12
  EXPECT_LT(MeanReprojectionError(reconstruction), 1e-6);
  EXPECT_EQ(reconstruction.GetCamera(1).params, truth.GetCamera(1).params);
}

TEST_P(BundleAdjustmentModelTest, RefinesFocalLengthAndDistortion) {
  const Reconstruction truth = MakeArcScene(GetParam(), 12, 400, 3);
  const BundleAdjustmentConfig config = GaugeFixedConfig(truth);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1, 2}, 0.5, 0.02, 0.02, 4);
  Camera& camera = reconstruction.GetCamera(1);
  const int num_focal = camera.model_id == CameraModelId::kPinhole ? 2 : 1;
  for (int i = 0; i < num_focal; ++i) camera.params[i] *= 1.05;
  const bool has_extra = camera.model_id == CameraModelId::kSimpleRadial;
  if (has_extra) camera.params[3] = -0.03;

  BundleAdjustmentOptions options;
  options.refine_focal_length = true;
  options.refine_extra_params = has_extra;
  BundleAdjuster adjuster(options, config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  EXPECT_EQ(adjuster.report().num_variable_cameras, 1);

  const std::vector<double>& refined = reconstruction.GetCamera(1).params;
  const std::vector<double>& expected = truth.GetCamera(1).params;
  for (int i = 0; i < num_focal; ++i) {
    EXPECT_LT(std::abs(refined[i] / expected[i] - 1.0), 1e-3) << "focal " << i;
  }
  // The principal point is not refined, so it stays bit-identical.
  for (int i = num_focal; i < num_focal + 2; ++i) EXPECT_EQ(refined[i], expected[i]);
  if (has_extra) {
    EXPECT_NEAR(refined[3], expected[3], 1e-5);
  }
  EXPECT_LT(ComparePoses(truth, reconstruction).max_rotation_deg, 0.01);
  EXPECT_LT(MeanReprojectionError(reconstruction), 1e-6);
}

// fx and fy of a camera without a prior move together (fy / fx stays as it was); with a
// prior they are refined separately and both recovered.
TEST(BundleAdjustment, KeepsTheAspectRatioOfUnknownCameras) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 400, 3);
  for (const bool prior : {false, true}) {
    Reconstruction reconstruction = truth;
    Perturb(&reconstruction, {1, 2}, 0.5, 0.02, 0.02, 4);
    Camera& camera = reconstruction.GetCamera(1);
    camera.has_prior_focal_length = prior;
    camera.params[0] *= 1.05;
    camera.params[1] *= 1.03;
    const double ratio = camera.params[1] / camera.params[0];
    BundleAdjustmentOptions options;
    options.refine_focal_length = true;
    BundleAdjuster adjuster(options, GaugeFixedConfig(truth));
    ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
    const std::vector<double>& refined = reconstruction.GetCamera(1).params;
    const std::vector<double>& expected = truth.GetCamera(1).params;
    if (prior) {
      EXPECT_LT(std::abs(refined[0] / expected[0] - 1.0), 1e-3);
      EXPECT_LT(std::abs(refined[1] / expected[1] - 1.0), 1e-3);
    } else {
      EXPECT_NEAR(refined[1] / refined[0], ratio, 1e-12);
      // The shared focal length moved towards the truth, between the two true values.
      EXPECT_LT(std::abs(refined[0] / expected[0] - 1.0), 0.03);
      EXPECT_GT(MeanReprojectionError(reconstruction), 1e-3) << "fy cannot reach the truth";
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Models, BundleAdjustmentModelTest,
                         ::testing::Values(CameraModelId::kPinhole, CameraModelId::kSimpleRadial));

TEST(BundleAdjustment, NoisyObservationsGiveErrorsAtTheNoiseLevel) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 400, 5);
  const BundleAdjustmentConfig config = GaugeFixedConfig(truth);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1, 2}, 0.8, 0.03, 0.03, 6);
  constexpr double kSigma = 0.5;
  AddPixelNoise(&reconstruction, kSigma, 7);
  BundleAdjustmentOptions options;
  options.loss_function = BundleLossFunction::kTrivial;
  BundleAdjuster adjuster(options, config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();

  // Mean norm of 2D Gaussian noise is sigma * sqrt(pi / 2) = 0.627 px; the fit absorbs a
  // little of it (3 of ~20 residuals per point go into the point).
  const double error = MeanReprojectionError(reconstruction);
  EXPECT_GT(error, 0.5);
  EXPECT_LT(error, 0.63);
  // Fixing the gauge through two images puts their noise into every other pose; compare
  // after a similarity alignment of all centres instead.
  const PoseErrors errors = ComparePoses(truth, AlignedToTruth(truth, reconstruction));
  // Rotation and translation errors are correlated (points span +-2 at a depth of ~6).
  EXPECT_LT(errors.max_rotation_deg, 0.1);
  EXPECT_LT(errors.max_centre, 0.01);  // scene size ~12
}

TEST(BundleAdjustment, RobustLossSeparatesOutliers) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kSimpleRadial, 12, 400, 8);
  const BundleAdjustmentConfig config = GaugeFixedConfig(truth);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1, 2}, 0.8, 0.03, 0.03, 9);
  // Moves 5% of the observations by 20-60 px.
  Random random(10);
  std::set<TrackElement> outliers;
  for (const auto& [id, point] : reconstruction.Points3D()) {
    for (const TrackElement& element : point.track.elements) {
      if (random.UniformReal() > 0.05) continue;
      const double angle = random.UniformReal(0, 2 * M_PI);
      reconstruction.GetImage(element.image_id).points2D[element.point2D_idx].xy +=
          random.UniformReal(20, 60) * Eigen::Vector2d(std::cos(angle), std::sin(angle));
      outliers.insert(element);
    }
  }
  ASSERT_GT(outliers.size(), 100u);

  BundleAdjustmentOptions options;
  options.loss_function = BundleLossFunction::kCauchy;
  BundleAdjuster robust(options, config);
  ASSERT_TRUE(robust.Solve(&reconstruction)) << robust.FullReport();
  EXPECT_LT(ComparePoses(truth, reconstruction).max_rotation_deg, 0.02);

  // The observations above 4 px are exactly the planted outliers.
  std::set<TrackElement> flagged;
  for (const auto& [id, point] : reconstruction.Points3D()) {
    for (const TrackElement& element : point.track.elements) {
      if (reconstruction.ReprojectionError(point, element).value_or(1e9) > 4.0) {
        flagged.insert(element);
      }
    }
  }
  EXPECT_EQ(flagged, outliers);
  for (const TrackElement& element : flagged) {
    if (reconstruction.GetImage(element.image_id).points2D[element.point2D_idx].HasPoint3D()) {
      reconstruction.DeleteObservation(element.image_id, element.point2D_idx);
    }
  }

  BundleAdjuster refine(options, config);
  ASSERT_TRUE(refine.Solve(&reconstruction)) << refine.FullReport();
  const PoseErrors errors = ComparePoses(truth, reconstruction);
  EXPECT_LT(errors.max_rotation_deg, 1e-6);
  EXPECT_LT(errors.max_centre, 1e-7);
  EXPECT_LT(MeanReprojectionError(reconstruction), 1e-6);
}

TEST(BundleAdjustment, ConstantBlocksStayExactlyConstant) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 300, 11);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1, 2}, 0.8, 0.03, 0.03, 12);
  BundleAdjustmentConfig config = AllImagesConfig(reconstruction);
  config.SetConstantPose(1);
  config.SetConstantPose(2);
  const point3D_t constant_point = reconstruction.Points3D().begin()->first;
  const Eigen::Vector3d constant_xyz = reconstruction.GetPoint3D(constant_point).xyz;
  config.AddConstantPoint(constant_point);
  config.SetConstantCamera(1);
  const Rigid3d pose1 = reconstruction.GetImage(1).cam_from_world;
  const Rigid3d pose2 = reconstruction.GetImage(2).cam_from_world;

  BundleAdjustmentOptions options;
  options.refine_focal_length = true;  // overridden by the constant camera
  BundleAdjuster adjuster(options, config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  EXPECT_EQ(adjuster.report().num_variable_images, 10);
  EXPECT_EQ(adjuster.report().num_variable_cameras, 0);
  EXPECT_EQ(reconstruction.GetImage(1).cam_from_world.rotation.coeffs(), pose1.rotation.coeffs());
  EXPECT_EQ(reconstruction.GetImage(1).cam_from_world.translation, pose1.translation);
  EXPECT_EQ(reconstruction.GetImage(2).cam_from_world.rotation.coeffs(), pose2.rotation.coeffs());
  EXPECT_EQ(reconstruction.GetImage(2).cam_from_world.translation, pose2.translation);
  EXPECT_EQ(reconstruction.GetPoint3D(constant_point).xyz, constant_xyz);
  EXPECT_EQ(reconstruction.GetCamera(1).params, truth.GetCamera(1).params);
}

TEST(BundleAdjustment, LocalBundleUsesOtherImagesAsConstantObservations) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 300, 13);
  Reconstruction reconstruction = truth;
  // Images 1-6 are "old" and exact; the newest six and all points are perturbed.
  Perturb(&reconstruction, {1, 2, 3, 4, 5, 6}, 0.8, 0.03, 0.03, 14);
  BundleAdjustmentConfig config;
  for (image_t id = 7; id <= 12; ++id) config.AddImage(id);
  const Reconstruction before = reconstruction;

  BundleAdjustmentOptions options = BundleAdjustmentOptions::Local();
  options.max_constant_observations_per_point = 0;
  BundleAdjuster adjuster(options, config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  EXPECT_EQ(adjuster.report().num_variable_images, 6);
  // Every observation of the points seen by the newest images is in the problem.
  size_t expected_blocks = 0;
  for (const auto& [id, point] : truth.Points3D()) {
    bool seen_by_new = false;
    for (const TrackElement& element : point.track.elements) seen_by_new |= element.image_id >= 7;
    if (seen_by_new) expected_blocks += point.track.Length();
  }
  EXPECT_EQ(adjuster.report().num_reprojection_residual_blocks, static_cast<int>(expected_blocks));

  for (image_t id = 1; id <= 6; ++id) {
    EXPECT_EQ(reconstruction.GetImage(id).cam_from_world.translation,
              before.GetImage(id).cam_from_world.translation);
  }
  // The old images fix the gauge, so the new poses return to the truth.
  for (image_t id = 7; id <= 12; ++id) {
    const Image& a = truth.GetImage(id);
    const Image& b = reconstruction.GetImage(id);
    EXPECT_LT(RotationAngleDegrees(a.cam_from_world.rotation * b.cam_from_world.rotation.inverse()),
              1e-6);
    EXPECT_LT((a.ProjectionCenter() - b.ProjectionCenter()).norm(), 1e-7);
  }
}

// A bundle restricted to some points holds only their observations; the other points stay
// exactly where they were, and the cameras still return to the truth.
TEST(BundleAdjustment, RestrictedToSomePointsLeavesTheOthersOut) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 300, 17);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1}, 0.8, 0.03, 0.03, 18);
  BundleAdjustmentConfig config = AllImagesConfig(reconstruction);
  config.SetConstantPose(1);
  config.SetConstantCentreCoords(2, {0});
  std::unordered_set<point3D_t> subset;
  size_t expected_blocks = 0;
  for (const auto& [id, point] : reconstruction.Points3D()) {
    if (id % 3 != 0) continue;
    subset.insert(id);
    expected_blocks += point.track.Length();
  }
  ASSERT_GT(subset.size(), 50u);
  ASSERT_LT(subset.size(), reconstruction.NumPoints3D());
  config.RestrictToPoints(subset);
  const Reconstruction before = reconstruction;

  BundleAdjuster adjuster(BundleAdjustmentOptions{}, config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  EXPECT_EQ(adjuster.report().num_reprojection_residual_blocks, static_cast<int>(expected_blocks));
  EXPECT_EQ(adjuster.report().num_variable_points, static_cast<int>(subset.size()));
  for (const auto& [id, point] : reconstruction.Points3D()) {
    if (subset.count(id) == 0) {
      EXPECT_EQ(point.xyz, before.GetPoint3D(id).xyz) << id;
    }
  }
  // Image 1 and one coordinate of image 2 fix the gauge up to the scale the perturbed
  // translation of image 2 sets; compare the others' centres after a similarity.
  std::vector<Eigen::Vector3d> estimated, expected;
  for (image_t id = 1; id <= 12; ++id) {
    estimated.push_back(reconstruction.GetImage(id).ProjectionCenter());
    expected.push_back(truth.GetImage(id).ProjectionCenter());
  }
  const auto sim3 = EstimateSim3(estimated, expected);
  ASSERT_TRUE(sim3.has_value());
  for (size_t k = 0; k < estimated.size(); ++k) {
    EXPECT_LT((*sim3 * estimated[k] - expected[k]).norm(), 1e-6) << "image " << k + 1;
  }
}

// With a cap on the anchoring observations, each point keeps at most that many of its
// observations by the old images, and the new images still return to the truth.
TEST(BundleAdjustment, LocalBundleCapsTheAnchoringObservationsOfEachPoint) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 300, 13);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1, 2, 3, 4, 5, 6}, 0.8, 0.03, 0.03, 14);
  BundleAdjustmentConfig config;
  for (image_t id = 7; id <= 12; ++id) config.AddImage(id);
  BundleAdjustmentOptions options = BundleAdjustmentOptions::Local();
  options.max_constant_observations_per_point = 2;
  BundleAdjuster adjuster(options, config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  size_t expected_blocks = 0, uncapped = 0;
  for (const auto& [id, point] : truth.Points3D()) {
    size_t inside = 0, outside = 0;
    for (const TrackElement& element : point.track.elements) (element.image_id >= 7 ? inside : outside)++;
    if (inside == 0) continue;
    expected_blocks += inside + std::min<size_t>(outside, 2);
    uncapped += inside + outside;
  }
  EXPECT_EQ(adjuster.report().num_reprojection_residual_blocks, static_cast<int>(expected_blocks));
  EXPECT_LT(expected_blocks, uncapped);
  for (image_t id = 7; id <= 12; ++id) {
    const Image& a = truth.GetImage(id);
    const Image& b = reconstruction.GetImage(id);
    EXPECT_LT(RotationAngleDegrees(a.cam_from_world.rotation * b.cam_from_world.rotation.inverse()),
              1e-6);
    EXPECT_LT((a.ProjectionCenter() - b.ProjectionCenter()).norm(), 1e-7);
  }
}

TEST(BundleAdjustment, ExtraDistanceResidualFixesTheScale) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 300, 15);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1}, 0.8, 0.03, 0.03, 16);
  // Only the first pose is fixed: the scale is left to the extra term.
  BundleAdjustmentConfig config = AllImagesConfig(reconstruction);
  config.SetConstantPose(1);
  BundleAdjuster adjuster(BundleAdjustmentOptions::Global(), config);
  adjuster.SetUp(&reconstruction);

  auto it = truth.Points3D().begin();
  const point3D_t id_a = (it++)->first;
  const point3D_t id_b = it->first;
  constexpr double kScale = 1.2;
  const double target = kScale * (truth.GetPoint3D(id_a).xyz - truth.GetPoint3D(id_b).xyz).norm();
  adjuster.problem().AddResidualBlock(PointDistanceCost::Create(target, 10.0), nullptr,
                                      adjuster.PointBlock(id_a), adjuster.PointBlock(id_b));
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  EXPECT_EQ(adjuster.report().num_residual_blocks,
            adjuster.report().num_reprojection_residual_blocks + 1);

  const double distance =
      (reconstruction.GetPoint3D(id_a).xyz - reconstruction.GetPoint3D(id_b).xyz).norm();
  EXPECT_NEAR(distance / target, 1.0, 1e-7);
  EXPECT_LT(MeanReprojectionError(reconstruction), 1e-6);
  // The whole model was scaled about the fixed first camera.
  const Eigen::Vector3d origin = truth.GetImage(1).ProjectionCenter();
  for (const image_t id : {5, 12}) {
    const Eigen::Vector3d expected =
        origin + kScale * (truth.GetImage(id).ProjectionCenter() - origin);
    EXPECT_LT((reconstruction.GetImage(id).ProjectionCenter() - expected).norm(), 1e-6);
  }
}

TEST(BundleAdjustment, PoseGraphThroughBlockAccessors) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 8, 50, 17);
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1}, 2.0, 0.2, 0.0, 18);
  BundleAdjuster adjuster(BundleAdjustmentOptions::Global(), BundleAdjustmentConfig());
  adjuster.SetUp(&reconstruction);
  EXPECT_FALSE(adjuster.HasPoseBlock(1));
  const std::vector<image_t> ids = truth.RegImageIds();
  for (size_t i = 0; i < ids.size(); ++i) {
    const image_t a = ids[i];
    const image_t b = ids[(i + 1) % ids.size()];  // a closed loop
    const Rigid3d b_from_a =
        truth.GetImage(b).cam_from_world * truth.GetImage(a).cam_from_world.Inverse();
    adjuster.problem().AddResidualBlock(
        RelativePoseCost::Create(b_from_a), nullptr, adjuster.PoseBlock(a), adjuster.PoseBlock(b));
  }
  adjuster.problem().SetParameterBlockConstant(adjuster.PoseBlock(1));
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  EXPECT_NE(adjuster.report().linear_solver.find("CHOLESKY"), std::string::npos);
  const PoseErrors errors = ComparePoses(truth, reconstruction);
  EXPECT_LT(errors.max_rotation_deg, 1e-6);
  EXPECT_LT(errors.max_centre, 1e-7);
}

TEST(BundleAdjustment, SparseAndIterativeSchurSolversConverge) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 300, 19);
  const BundleAdjustmentConfig config = GaugeFixedConfig(truth);
  for (const BundleLinearSolver solver :
       {BundleLinearSolver::kSparseSchur, BundleLinearSolver::kIterativeSchur}) {
    Reconstruction reconstruction = truth;
    Perturb(&reconstruction, {1, 2}, 0.8, 0.03, 0.03, 20);
    BundleAdjustmentOptions options;
    options.linear_solver = solver;
    BundleAdjuster adjuster(options, config);
    ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
    EXPECT_EQ(adjuster.report().linear_solver,
              solver == BundleLinearSolver::kSparseSchur ? "SPARSE_SCHUR" : "ITERATIVE_SCHUR");
    EXPECT_LT(ComparePoses(truth, reconstruction).max_rotation_deg, 1e-5);
    EXPECT_LT(MeanReprojectionError(reconstruction), 1e-5);
  }
}

TEST(BundleAdjustment, SettleToleranceEndsTheSolveOnceTheCamerasSettle) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 400, 23);
  const BundleAdjustmentConfig config = GaugeFixedConfig(truth);
  Reconstruction start = truth;
  Perturb(&start, {1, 2}, 0.8, 0.03, 0.03, 24);
  AddPixelNoise(&start, 0.5, 25);
  start.GetCamera(1).params[0] *= 1.02;
  start.GetCamera(1).params[1] *= 1.02;
  // Without Ceres' own tolerances the solver takes every step it is allowed.
  BundleAdjustmentOptions options;
  options.refine_focal_length = true;
  options.function_tolerance = 0.0;
  options.gradient_tolerance = 0.0;
  options.parameter_tolerance = 0.0;
  options.max_num_iterations = 40;
  options.num_threads = 1;  // the same steps on every run
  Reconstruction full = start;
  BundleAdjuster full_adjuster(options, config);
  ASSERT_TRUE(full_adjuster.Solve(&full)) << full_adjuster.FullReport();
  EXPECT_FALSE(full_adjuster.report().settled);

  options.settle_tolerance = 1e-6;
  Reconstruction settled = start;
  BundleAdjuster settled_adjuster(options, config);
  ASSERT_TRUE(settled_adjuster.Solve(&settled)) << settled_adjuster.FullReport();
  EXPECT_TRUE(settled_adjuster.report().settled);
  EXPECT_LE(settled_adjuster.report().num_iterations, 12);
  EXPECT_GT(full_adjuster.report().num_iterations, settled_adjuster.report().num_iterations);
  // Where it stopped, the poses are those of the full solve, well below the noise's effect
  // on them (a centre error of ~1e-2 against the truth, scene size ~12).
  const PoseErrors difference = ComparePoses(full, settled);
  EXPECT_LT(difference.max_centre, 2e-5);
  EXPECT_LT(difference.max_rotation_deg, 2e-4);
  EXPECT_NEAR(settled.GetCamera(1).params[0], full.GetCamera(1).params[0], 1e-3);  // 400 px
  const PoseErrors error = ComparePoses(truth, AlignedToTruth(truth, settled));
  EXPECT_GT(error.max_centre, 10 * difference.max_centre);
}

// The second gauge image's held centre coordinate stays put while its rotation is corrected,
// however far the world's origin is: the scale gauge is a length between the two gauge
// centres, not a coordinate of t = -R c (which the image's turn alone moves, by the angle
// times the origin's distance: 0.7 deg at about 1000 units here).
TEST(BundleAdjustment, GaugeCentreCoordinateIsHeldFarFromTheOrigin) {
  Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 10, 300, 41);
  const Eigen::Vector3d offset(500.0, -300.0, 800.0);  // the arc spans a few units
  for (const image_t id : truth.RegImageIds()) {
    Rigid3d& pose = truth.GetImage(id).cam_from_world;
    pose.translation -= pose.rotation * offset;
  }
  for (auto& [id, point] : truth.Points3D()) point.xyz += offset;
  BundleAdjustmentConfig config = AllImagesConfig(truth);
  FixGaugeWithTwoImages(truth, 1, 2, &config);
  const int held = config.ConstantCentreCoords(2)->front();
  Reconstruction reconstruction = truth;
  Perturb(&reconstruction, {1, 2}, 0.8, 0.03, 0.03, 42);
  PerturbSecondGaugeImage(&reconstruction, held);
  const Eigen::Vector3d start = reconstruction.GetImage(2).ProjectionCenter();
  ASSERT_NEAR(start[held], truth.GetImage(2).ProjectionCenter()[held], 1e-9);

  BundleAdjuster adjuster(BundleAdjustmentOptions{}, config);
  ASSERT_TRUE(adjuster.Solve(&reconstruction)) << adjuster.FullReport();
  const double spread = (truth.GetImage(2).ProjectionCenter() -
                         truth.GetImage(1).ProjectionCenter()).norm();
  EXPECT_NEAR(reconstruction.GetImage(2).ProjectionCenter()[held], start[held], 1e-6 * spread);
  // The rest converges to the truth (2e-7 deg and 2e-7 units here; Ceres stops at its
  // function tolerance, not at machine precision).
  const PoseErrors errors = ComparePoses(truth, reconstruction);
  EXPECT_LT(errors.max_rotation_deg, 1e-5);
  EXPECT_LT(errors.max_centre, 1e-5 * spread);
}

TEST(BundleAdjustment, GaugeFixUsesTheLargestComponent) {
  const Reconstruction truth = MakeArcScene(CameraModelId::kPinhole, 12, 50, 21);
  BundleAdjustmentConfig config;
  FixGaugeWithTwoImages(truth, 1, 12, &config);
  EXPECT_TRUE(config.HasConstantPose(1));
  EXPECT_FALSE(config.HasConstantPose(12));
  const Eigen::Vector3d baseline =
      truth.GetImage(12).ProjectionCenter() - truth.GetImage(1).ProjectionCenter();
  int expected = 0;
  baseline.cwiseAbs().maxCoeff(&expected);
  ASSERT_NE(config.ConstantCentreCoords(12), nullptr);
  EXPECT_EQ(*config.ConstantCentreCoords(12), std::vector<int>{expected});
}

TEST(BundleAdjustment, ScaleGaugeIsTheRegisteredFrameFarthestFromTheFirst) {
  Reconstruction scene = MakeArcScene(CameraModelId::kPinhole, 12, 50, 21);
  auto farthest_by_search = [&](image_t from) {
    image_t best = 0;
    double largest = -1.0;
    for (const image_t id : scene.RegImageIds()) {
      const double d =
          (scene.GetImage(id).ProjectionCenter() - scene.GetImage(from).ProjectionCenter()).norm();
      if (d > largest) {
        largest = d;
        best = id;
      }
    }
    return best;
  };
  const image_t farthest = farthest_by_search(1);
  ASSERT_NE(farthest, 2u);
  EXPECT_EQ(FarthestRegisteredImage(scene, 1, 2), farthest);
  // Frames not registered are not taken; the fallback stays when none is farther.
  scene.DeRegisterImage(farthest);
  EXPECT_EQ(FarthestRegisteredImage(scene, 1, 2), farthest_by_search(1));
  for (const image_t id : scene.RegImageIds()) {
    if (id != 1 && id != 2) scene.DeRegisterImage(id);
  }
  EXPECT_EQ(FarthestRegisteredImage(scene, 1, 2), 2u);
}

TEST(BundleAdjustment, OptionsCheckRejectsBadValues) {
  BundleAdjustmentOptions options;
  EXPECT_NO_THROW(options.Check());
  options.loss_function_scale = 0.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = BundleAdjustmentOptions();
  options.max_num_iterations = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = BundleAdjustmentOptions();
  options.settle_tolerance = -1e-6;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = BundleAdjustmentOptions();
  options.dense_schur_max_num_images = 2000;
  EXPECT_THROW(BundleAdjuster(options, BundleAdjustmentConfig()), InvalidArgument);
}

std::vector<double> ToVector(const Eigen::VectorXd& v) { return {v.data(), v.data() + v.size()}; }
// The 7 parameters of a pose block: quaternion x, y, z, w, then the translation.
std::vector<double> PoseVector(const Rigid3d& pose) {
  return {PoseParameters(pose), PoseParameters(pose) + 7};
}

// Compares a cost function's Jacobians with central differences in the ambient space.
void ExpectJacobiansMatchFiniteDifferences(const ceres::CostFunction& cost,
                                           std::vector<std::vector<double>> blocks) {
  const int num_residuals = cost.num_residuals();
  const std::vector<int32_t>& sizes = cost.parameter_block_sizes();
  ASSERT_EQ(sizes.size(), blocks.size());
  std::vector<const double*> parameters;
  std::vector<std::vector<double>> jacobians(blocks.size());
  std::vector<double*> jacobian_ptrs;
  for (size_t b = 0; b < blocks.size(); ++b) {
    ASSERT_EQ(static_cast<int>(blocks[b].size()), sizes[b]);
    parameters.push_back(blocks[b].data());
    jacobians[b].resize(num_residuals * sizes[b]);
    jacobian_ptrs.push_back(jacobians[b].data());
  }
  std::vector<double> residuals(num_residuals), plus(num_residuals), minus(num_residuals);
  ASSERT_TRUE(cost.Evaluate(parameters.data(), residuals.data(), jacobian_ptrs.data()));
  for (size_t b = 0; b < blocks.size(); ++b) {
    for (int k = 0; k < sizes[b]; ++k) {
      const double x = blocks[b][k];
      const double h = 1e-6 * std::max(1.0, std::abs(x));
      blocks[b][k] = x + h;
      ASSERT_TRUE(cost.Evaluate(parameters.data(), plus.data(), nullptr));
      blocks[b][k] = x - h;
      ASSERT_TRUE(cost.Evaluate(parameters.data(), minus.data(), nullptr));
      blocks[b][k] = x;
      for (int r = 0; r < num_residuals; ++r) {
        const double numeric = (plus[r] - minus[r]) / (2 * h);
        const double analytic = jacobians[b][r * sizes[b] + k];
        EXPECT_NEAR(analytic, numeric, 1e-6 * std::max(1.0, std::abs(analytic)))
            << "block " << b << " param " << k << " residual " << r;
      }
    }
  }
}

class ReprojectionCostTest : public ::testing::TestWithParam<CameraModelId> {};

TEST_P(ReprojectionCostTest, MatchesCameraProjectionAndFiniteDifferences) {
  const Camera camera = MakeCamera(GetParam(), 500.0);
  Random random(23);
  const Rigid3d cam_from_world(SmallRotation(random, 20.0), Eigen::Vector3d(0.3, -0.2, 0.5));
  const Eigen::Vector3d point(0.4, 0.3, 4.0);
  const Eigen::Vector2d observed(300.0, 200.0);
  const Eigen::Vector2d expected = camera.ImgFromCam(cam_from_world * point) - observed;

  std::unique_ptr<ceres::CostFunction> cost(CreateReprojectionErrorCost(camera.model_id, observed));
  std::vector<std::vector<double>> blocks = {PoseVector(cam_from_world), ToVector(point),
                                             camera.params};
  std::vector<const double*> parameters;
  for (const auto& block : blocks) parameters.push_back(block.data());
  Eigen::Vector2d residuals;
  ASSERT_TRUE(cost->Evaluate(parameters.data(), residuals.data(), nullptr));
  EXPECT_LT((residuals - expected).norm(), 1e-9);
  ExpectJacobiansMatchFiniteDifferences(*cost, blocks);

  std::unique_ptr<ceres::CostFunction> constant_pose(
      CreateReprojectionErrorConstantPoseCost(camera.model_id, cam_from_world, observed));
  std::vector<std::vector<double>> point_blocks = {blocks[1], blocks[2]};
  std::vector<const double*> point_parameters = {point_blocks[0].data(), point_blocks[1].data()};
  ASSERT_TRUE(constant_pose->Evaluate(point_parameters.data(), residuals.data(), nullptr));
  EXPECT_LT((residuals - expected).norm(), 1e-9);
  ExpectJacobiansMatchFiniteDifferences(*constant_pose, point_blocks);

  // The camera as data: same residuals, derivatives for the remaining blocks only.
  std::unique_ptr<ceres::CostFunction> constant_camera(
      CreateReprojectionErrorConstantCameraCost(camera.model_id, camera.params, observed));
  std::vector<std::vector<double>> pose_point_blocks = {blocks[0], blocks[1]};
  std::vector<const double*> pose_point_parameters;
  for (const auto& block : pose_point_blocks) pose_point_parameters.push_back(block.data());
  ASSERT_TRUE(constant_camera->Evaluate(pose_point_parameters.data(), residuals.data(), nullptr));
  EXPECT_LT((residuals - expected).norm(), 1e-9);
  ExpectJacobiansMatchFiniteDifferences(*constant_camera, pose_point_blocks);

  std::unique_ptr<ceres::CostFunction> constant_pose_camera(
      CreateReprojectionErrorConstantPoseCameraCost(camera.model_id, cam_from_world, camera.params,
                                                    observed));
  std::vector<std::vector<double>> only_point = {blocks[1]};
  const double* only_point_parameters[] = {only_point[0].data()};
  ASSERT_TRUE(constant_pose_camera->Evaluate(only_point_parameters, residuals.data(), nullptr));
  EXPECT_LT((residuals - expected).norm(), 1e-9);
  ExpectJacobiansMatchFiniteDifferences(*constant_pose_camera, only_point);
}

// The hand-written derivatives of the full cost and of the constant-camera cost against
// automatic differentiation of the definition (ReprojectionErrorAutoDiff), at a unit
// quaternion and at one off the unit sphere, where all differentiate the same expression.
TEST_P(ReprojectionCostTest, AnalyticDerivativesEqualAutomaticDifferentiation) {
  const Camera camera = MakeCamera(GetParam(), 500.0);
  Random random(31);
  const Eigen::Vector2d observed(310.0, 190.0);
  std::unique_ptr<ceres::CostFunction> reference(
      CreateReprojectionErrorAutoDiffCost(camera.model_id, observed));
  std::unique_ptr<ceres::CostFunction> full(CreateReprojectionErrorCost(camera.model_id, observed));
  std::unique_ptr<ceres::CostFunction> constant_camera(
      CreateReprojectionErrorConstantCameraCost(camera.model_id, camera.params, observed));
  const int sizes[] = {7, 3, static_cast<int>(camera.params.size())};
  for (const double quaternion_scale : {1.0, 1.3}) {
    Eigen::Matrix<double, 7, 1> pose;
    pose << SmallRotation(random, 35.0).coeffs() * quaternion_scale, 0.3, -0.2, 0.5;
    const Eigen::Vector3d point(-0.6, 0.4, 3.5);
    const double* parameters[] = {pose.data(), point.data(), camera.params.data()};
    std::vector<std::vector<double>> expected(3);
    std::vector<double*> expected_ptrs;
    for (int b = 0; b < 3; ++b) {
      expected[b].resize(2 * sizes[b]);
      expected_ptrs.push_back(expected[b].data());
    }
    Eigen::Vector2d expected_residuals;
    ASSERT_TRUE(reference->Evaluate(parameters, expected_residuals.data(), expected_ptrs.data()));
    for (const ceres::CostFunction* cost : {full.get(), constant_camera.get()}) {
      const int num_blocks = static_cast<int>(cost->parameter_block_sizes().size());
      std::vector<std::vector<double>> actual(num_blocks);
      std::vector<double*> actual_ptrs;
      for (int b = 0; b < num_blocks; ++b) {
        actual[b].resize(2 * sizes[b]);
        actual_ptrs.push_back(actual[b].data());
      }
      Eigen::Vector2d actual_residuals;
      ASSERT_TRUE(cost->Evaluate(parameters, actual_residuals.data(), actual_ptrs.data()));
      EXPECT_LT((actual_residuals - expected_residuals).norm(),
                1e-12 * std::max(1.0, expected_residuals.norm()));
      for (int b = 0; b < num_blocks; ++b) {
        for (int k = 0; k < 2 * sizes[b]; ++k) {
          EXPECT_NEAR(actual[b][k], expected[b][k],
                      1e-10 * std::max(1.0, std::abs(expected[b][k])))
              << num_blocks << " blocks, scale " << quaternion_scale << " block " << b
              << " entry " << k;
        }
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Models, ReprojectionCostTest, ::testing::ValuesIn(kCameraModelIds));

TEST(CostFunctions, DistanceAndRelativePoseJacobiansMatchFiniteDifferences) {
  std::unique_ptr<ceres::CostFunction> distance(PointDistanceCost::Create(1.5, 2.0));
  ExpectJacobiansMatchFiniteDifferences(*distance, {{0.1, 0.2, 0.3}, {1.0, -0.5, 0.8}});

  Random random(29);
  const Rigid3d measured(SmallRotation(random, 30.0), Eigen::Vector3d(1.0, 0.2, -0.3));
  Eigen::Matrix<double, 6, 6> sqrt_information = Eigen::Matrix<double, 6, 6>::Identity();
  sqrt_information(3, 3) = 5.0;
  std::unique_ptr<ceres::CostFunction> relative(
      RelativePoseCost::Create(measured, sqrt_information));
  const Eigen::Quaterniond qa = SmallRotation(random, 40.0);
  const Eigen::Quaterniond qb = SmallRotation(random, 40.0);
  ExpectJacobiansMatchFiniteDifferences(
      *relative, {PoseVector(Rigid3d(qa, Eigen::Vector3d(0.1, 0.2, 0.3))),
                  PoseVector(Rigid3d(qb, Eigen::Vector3d(-0.4, 0.5, 0.6)))});

  // At the measured relative pose the residual vanishes.
  const Rigid3d cam_a(qa, Eigen::Vector3d(0.1, 0.2, 0.3));
  const Rigid3d cam_b = measured * cam_a;
  const double* parameters[] = {PoseParameters(cam_a), PoseParameters(cam_b)};
  Eigen::Matrix<double, 6, 1> residuals;
  ASSERT_TRUE(relative->Evaluate(parameters, residuals.data(), nullptr));
  EXPECT_LT(residuals.norm(), 1e-12);
}

// The split-track tie: the separation in pixels as the observer sees it, unchanged by a
// similarity of the whole model (a tie in world units shrinks with the model, and a bundle
// held by a gauge at two frames then lowers it by tearing those frames off).
TEST(CostFunctions, DepthScaledCoincidenceIsInPixelsAndFreeOfTheModelsScale) {
  Random random(31);
  const Rigid3d cam_from_world(SmallRotation(random, 30.0), Eigen::Vector3d(0.2, -0.1, 0.4));
  const Eigen::Vector3d a(0.3, 0.1, 4.0), b(0.35, 0.05, 4.2);
  std::unique_ptr<ceres::CostFunction> cost(DepthScaledCoincidenceCost::Create(500.0));
  const auto residuals_at = [&](const Rigid3d& pose, const Eigen::Vector3d& pa,
                                const Eigen::Vector3d& pb) {
    const double* parameters[] = {pa.data(), pb.data(), PoseParameters(pose)};
    Eigen::Vector3d residuals;
    EXPECT_TRUE(cost->Evaluate(parameters, residuals.data(), nullptr));
    return residuals;
  };
  const Eigen::Vector3d residuals = residuals_at(cam_from_world, a, b);
  const double depth = (cam_from_world * (0.5 * (a + b))).z();
  EXPECT_LT((residuals - 500.0 * (a - b) / depth).norm(), 1e-12);

  // X' = s Q X + d; cam_from_world' = (R Q^T, s t - R Q^T d) sees X' at s times p.
  const double s = 3.7;
  const Eigen::Quaterniond q = SmallRotation(random, 50.0);
  const Eigen::Vector3d d(5.0, -2.0, 1.0);
  const Eigen::Quaterniond rotation = (cam_from_world.rotation * q.conjugate()).normalized();
  const Rigid3d moved(rotation, s * cam_from_world.translation - (rotation * d));
  const Eigen::Vector3d moved_residuals = residuals_at(moved, s * (q * a) + d, s * (q * b) + d);
  EXPECT_NEAR(moved_residuals.norm(), residuals.norm(), 1e-9 * residuals.norm());
  EXPECT_GT(residuals.norm(), 1.0);

  ExpectJacobiansMatchFiniteDifferences(
      *cost, {ToVector(a), ToVector(b), PoseVector(cam_from_world)});

  // Behind the observer the term is not finite: the solver must reject such a step.
  const Eigen::Vector3d behind_a = -a, behind_b = -b;
  const Rigid3d identity;
  const double* parameters[] = {behind_a.data(), behind_b.data(), PoseParameters(identity)};
  Eigen::Vector3d unused;
  EXPECT_FALSE(cost->Evaluate(parameters, unused.data(), nullptr));
}

}  // namespace
}  // namespace loopsfm

namespace loopsfm {
namespace {

TEST(FocalPriorCost, PenalisesTheLogRatioWithTheRightJacobian) {
  const FocalPriorCost cost(/*num_params=*/4, /*focal_px=*/800.0, /*sigma_log=*/0.2);
  double params[4] = {800.0, 320.0, 240.0, -0.1};
  const double* blocks[1] = {params};
  double residual = 1.0;
  double jacobian[4];
  double* jacobians[1] = {jacobian};
  ASSERT_TRUE(cost.Evaluate(blocks, &residual, jacobians));
  EXPECT_NEAR(residual, 0.0, 1e-15);
  params[0] = 960.0;
  ASSERT_TRUE(cost.Evaluate(blocks, &residual, jacobians));
  EXPECT_NEAR(residual, std::log(1.2) / 0.2, 1e-12);
  // Finite difference of the residual in the focal length; nothing else moves it.
  double shifted = 0.0;
  params[0] += 1e-4;
  ASSERT_TRUE(cost.Evaluate(blocks, &shifted, nullptr));
  EXPECT_NEAR(jacobian[0], (shifted - residual) / 1e-4, 1e-6);
  for (int i = 1; i < 4; ++i) EXPECT_EQ(jacobian[i], 0.0);
  params[0] = -5.0;
  EXPECT_FALSE(cost.Evaluate(blocks, &residual, nullptr)) << "a non-positive focal length is no step";
}

}  // namespace
}  // namespace loopsfm
