#include "loopsfm/estimators/global_positioning.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "loopsfm/geometry/umeyama.h"
#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

struct Scene {
  GlobalPositioningInput input;
  std::map<image_t, Eigen::Vector3d> true_centres;
  std::map<point3D_t, Eigen::Vector3d> true_points;
};

Eigen::Vector3d RandomUnit(Random& random) {
  Eigen::Vector3d v(random.Normal(), random.Normal(), random.Normal());
  return v.normalized();
}

// cam_from_world of a camera at `centre` whose optical axis (z) points at `target`; `up`
// (not parallel to the axis) sets the roll.
Eigen::Quaterniond LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target,
                          const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = up.cross(z).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_from_cam;
  world_from_cam << x, y, z;
  return Eigen::Quaterniond(world_from_cam.transpose());
}

// The bearing turned by a random rotation with components of standard deviation sigma.
Eigen::Vector3d Perturb(const Eigen::Vector3d& bearing, double sigma, Random& random) {
  const Eigen::Vector3d axis_angle(random.Normal(0, sigma), random.Normal(0, sigma),
                                   random.Normal(0, sigma));
  if (axis_angle.norm() == 0.0) return bearing;
  return Eigen::AngleAxisd(axis_angle.norm(), axis_angle.normalized()) * bearing;
}

// Each camera observes, with the given probability, every point that lies in front of it
// within the half field of view and the range, with noisy bearings.
void Observe(Scene* scene, double half_fov_deg, double max_range, double probability,
             double noise_rad, Random& random) {
  const double max_angle = half_fov_deg * M_PI / 180.0;
  for (const auto& [image_id, centre] : scene->true_centres) {
    const Eigen::Quaterniond& rotation = scene->input.cam_from_world_rotations.at(image_id);
    for (const auto& [point_id, point] : scene->true_points) {
      const Eigen::Vector3d in_cam = rotation * (point - centre);
      if (in_cam.z() <= 0.0 || in_cam.norm() > max_range) continue;
      if (std::atan2(in_cam.head<2>().norm(), in_cam.z()) > max_angle) continue;
      if (random.UniformReal() >= probability) continue;
      scene->input.observations.push_back(
          {image_id, point_id, Perturb(in_cam.normalized(), noise_rad, random)});
    }
  }
}

// Cameras on a shell of radius 12 to 18 around a box of points of half-side 5, each
// looking at a random spot near the centre with a random roll.
Scene RandomScene(int num_cameras, int num_points, double noise_rad, uint64_t seed) {
  Random random(seed);
  Scene scene;
  for (int i = 0; i < num_cameras; ++i) {
    const Eigen::Vector3d centre = random.UniformReal(12.0, 18.0) * RandomUnit(random);
    const Eigen::Vector3d target(random.UniformReal(-2, 2), random.UniformReal(-2, 2),
                                 random.UniformReal(-2, 2));
    const image_t id = static_cast<image_t>(10 + 3 * i);  // ids need not be contiguous
    scene.true_centres[id] = centre;
    scene.input.cam_from_world_rotations[id] = LookAt(centre, target, RandomUnit(random));
  }
  for (int p = 0; p < num_points; ++p) {
    scene.true_points[static_cast<point3D_t>(1000 + p)] = Eigen::Vector3d(
        random.UniformReal(-5, 5), random.UniformReal(-5, 5), random.UniformReal(-5, 5));
  }
  Observe(&scene, 40.0, 100.0, 0.25, noise_rad, random);
  return scene;
}

// Video-like forward motion: cameras one unit apart along the z axis (a few hundredths of
// lateral jitter), each looking ahead with a small random tilt; points in a corridor of
// walls around the path, seen by the cameras they are ahead of, up to 30 units away.
Scene ForwardScene(int num_cameras, int num_points, double noise_rad, uint64_t seed) {
  Random random(seed);
  Scene scene;
  for (int i = 0; i < num_cameras; ++i) {
    const Eigen::Vector3d centre(random.Normal(0, 0.02), random.Normal(0, 0.02), i);
    const Eigen::Vector3d target = centre + Eigen::Vector3d(random.Normal(0, 0.05),
                                                            random.Normal(0, 0.05), 1.0);
    scene.true_centres[i] = centre;
    scene.input.cam_from_world_rotations[i] = LookAt(centre, target, Eigen::Vector3d::UnitY());
  }
  for (int p = 0; p < num_points; ++p) {
    Eigen::Vector3d point(random.UniformReal(-4, 4), random.UniformReal(-3, 3),
                          random.UniformReal(2, num_cameras + 5.0));
    if (std::abs(point.x()) < 1.5 && std::abs(point.y()) < 1.5) point.x() += 3.0;
    scene.true_points[p] = point;
  }
  Observe(&scene, 45.0, 30.0, 0.6, noise_rad, random);
  return scene;
}

// Video-like: a camera orbiting a box of points at radius 6, looking at its middle, with
// steps of step_a along the arc for its first num_a frames and step_b after them. Each point
// is seen by a run of 2 to max_track_length consecutive frames from a random one, so the two
// parts are tied only by the tracks that span the change. The initial centres are a chained
// start as the global mapper makes (consecutive frames one unit apart along their true
// direction), so the two parts start at the wrong relative scale.
Scene TwoPaceOrbitScene(int num_a, double step_a, int num_b, double step_b, int max_track_length,
                        double noise_rad, uint64_t seed) {
  Random random(seed);
  Scene scene;
  double arc = 0.0;
  for (int i = 0; i < num_a + num_b; ++i) {
    if (i > 0) arc += i < num_a ? step_a : step_b;
    const Eigen::Vector3d centre(6.0 * std::cos(arc / 6.0), 6.0 * std::sin(arc / 6.0),
                                 random.Normal(0, 0.05));
    const Eigen::Vector3d target(random.Normal(0, 0.2), random.Normal(0, 0.2), 0.0);
    scene.true_centres[i] = centre;
    scene.input.cam_from_world_rotations[i] = LookAt(centre, target, Eigen::Vector3d::UnitZ());
  }
  const int num_frames = num_a + num_b;
  for (int p = 0; p < 1500; ++p) {
    const Eigen::Vector3d point(random.UniformReal(-2, 2), random.UniformReal(-2, 2),
                                random.UniformReal(-2, 2));
    scene.true_points[p] = point;
    const int first = static_cast<int>(random.UniformReal(0, num_frames - 2));
    const int length = 2 + static_cast<int>(random.UniformReal(0, max_track_length - 1));
    for (int i = first; i < std::min(num_frames, first + length); ++i) {
      const Eigen::Vector3d in_cam =
          scene.input.cam_from_world_rotations.at(i) * (point - scene.true_centres.at(i));
      scene.input.observations.push_back({static_cast<image_t>(i), static_cast<point3D_t>(p),
                                          Perturb(in_cam.normalized(), noise_rad, random)});
    }
  }
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int i = 0; i < num_frames; ++i) {
    if (i > 0) centre += (scene.true_centres.at(i) - scene.true_centres.at(i - 1)).normalized();
    scene.input.initial_centres[i] = centre;
  }
  return scene;
}

// The path length of cameras first..last (consecutive ids) in the result over the truth's.
double PathScale(const GlobalPositioningResult& result, const Scene& scene, image_t first,
                 image_t last) {
  double estimated = 0.0, truth = 0.0;
  for (image_t i = first; i < last; ++i) {
    estimated += (result.camera_centres.at(i + 1) - result.camera_centres.at(i)).norm();
    truth += (scene.true_centres.at(i + 1) - scene.true_centres.at(i)).norm();
  }
  return estimated / truth;
}

struct Errors {
  double centre_rms = 0.0;  // relative to the scene's extent
  double point_rms = 0.0;   // relative to the scene's extent
  double alignment_rotation_deg = 0.0;
};

// Aligns the estimate to the truth with one similarity over cameras and points together
// (but the ignored points) and measures the RMS position errors as fractions of the
// truth's bounding-box diagonal.
Errors AlignedErrors(const GlobalPositioningResult& result, const Scene& scene,
                     const std::set<point3D_t>& ignored_points = {}) {
  std::vector<Eigen::Vector3d> estimate, truth;
  for (const auto& [id, centre] : result.camera_centres) {
    estimate.push_back(centre);
    truth.push_back(scene.true_centres.at(id));
  }
  const size_t num_cameras = estimate.size();
  for (const auto& [id, point] : result.points) {
    if (ignored_points.count(id)) continue;
    estimate.push_back(point);
    truth.push_back(scene.true_points.at(id));
  }
  Eigen::Vector3d lo = truth[0], hi = truth[0];
  for (const Eigen::Vector3d& x : truth) {
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  const double extent = (hi - lo).norm();
  const std::optional<Sim3d> truth_from_estimate = EstimateSim3(estimate, truth);
  Errors errors;
  if (!truth_from_estimate) {
    errors.centre_rms = errors.point_rms = errors.alignment_rotation_deg = 1e9;
    return errors;
  }
  double centre_sq = 0.0, point_sq = 0.0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    const double sq = ((*truth_from_estimate) * estimate[i] - truth[i]).squaredNorm();
    (i < num_cameras ? centre_sq : point_sq) += sq;
  }
  const size_t num_points = estimate.size() - num_cameras;
  errors.centre_rms = std::sqrt(centre_sq / num_cameras) / extent;
  errors.point_rms = num_points > 0 ? std::sqrt(point_sq / num_points) / extent : 0.0;
  errors.alignment_rotation_deg =
      Eigen::AngleAxisd(truth_from_estimate->rotation).angle() * 180.0 / M_PI;
  return errors;
}

void RecordErrors(const Errors& errors) {
  ::testing::Test::RecordProperty("centre_rms_relative", std::to_string(errors.centre_rms));
  ::testing::Test::RecordProperty("point_rms_relative", std::to_string(errors.point_rms));
  ::testing::Test::RecordProperty("alignment_rotation_deg",
                                  std::to_string(errors.alignment_rotation_deg));
}

// Replaces about the given fraction of the bearings with random directions. Returns how
// many were replaced.
int CorruptBearings(Scene* scene, double fraction, uint64_t seed) {
  Random random(seed);
  int num_corrupted = 0;
  for (BearingObservation& obs : scene->input.observations) {
    if (random.UniformReal() >= fraction) continue;
    obs.bearing_in_cam = RandomUnit(random);
    ++num_corrupted;
  }
  return num_corrupted;
}

// Points that no method can place from the corrupted bearings: those with fewer than two
// clean bearings (one ray leaves the depth free), and those with two next to a random one
// (every pair of the three rays meets somewhere, and each meeting explains two of them).
std::set<point3D_t> Undetermined(const Scene& scene) {
  std::map<point3D_t, std::pair<int, int>> counts;  // clean, corrupted
  for (const BearingObservation& obs : scene.input.observations) {
    const Eigen::Vector3d in_cam = scene.input.cam_from_world_rotations.at(obs.image_id) *
                                   (scene.true_points.at(obs.point_id) -
                                    scene.true_centres.at(obs.image_id));
    const bool clean = in_cam.normalized().dot(obs.bearing_in_cam.normalized()) > std::cos(0.01);
    ++(clean ? counts[obs.point_id].first : counts[obs.point_id].second);
  }
  std::set<point3D_t> undetermined;
  for (const auto& [id, count] : counts) {
    const auto [num_clean, num_corrupted] = count;
    if (num_clean < (num_corrupted > 0 ? 3 : 2)) undetermined.insert(id);
  }
  return undetermined;
}

GlobalPositioningOptions TestOptions() {
  GlobalPositioningOptions options;
  options.num_threads = 2;
  options.seed = 7;
  return options;
}

TEST(GlobalPositioning, RecoversRandomSceneUpToSimilarity) {
  const Scene scene = RandomScene(40, 1500, 0.001, 11);
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, TestOptions());
  const GlobalPositioningReport& report = result.report;
  ASSERT_TRUE(report.success) << report.termination;
  EXPECT_EQ(report.num_cameras, 40);
  std::map<point3D_t, int> views;
  for (const BearingObservation& obs : scene.input.observations) ++views[obs.point_id];
  int num_seen_twice = 0, num_used_observations = 0;
  for (const auto& [id, count] : views) {
    if (count < 2) continue;
    ++num_seen_twice;
    num_used_observations += count;
  }
  EXPECT_EQ(report.num_points, num_seen_twice);
  EXPECT_EQ(report.num_skipped_points, static_cast<int>(views.size()) - num_seen_twice);
  EXPECT_EQ(report.num_observations, num_used_observations);
  EXPECT_EQ(static_cast<int>(result.points.size()), report.num_points);
  EXPECT_LT(report.final_cost, report.initial_cost);
  const Errors errors = AlignedErrors(result, scene);
  RecordErrors(errors);
  EXPECT_LT(errors.centre_rms, 0.01);
  EXPECT_LT(errors.point_rms, 0.01);
  // Rotations are known, so the estimate differs from the truth by translation and scale.
  EXPECT_LT(errors.alignment_rotation_deg, 0.5);
  EXPECT_EQ(report.num_large_angle_observations, 0);
}

TEST(GlobalPositioning, RecoversNearlyCollinearForwardMotion) {
  const Scene scene = ForwardScene(60, 1500, 0.001, 21);
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, TestOptions());
  ASSERT_TRUE(result.report.success) << result.report.termination;
  EXPECT_EQ(result.report.num_cameras, 60);
  const Errors errors = AlignedErrors(result, scene);
  RecordErrors(errors);
  EXPECT_LT(errors.centre_rms, 0.01);
  EXPECT_LT(errors.point_rms, 0.01);
  EXPECT_LT(errors.alignment_rotation_deg, 0.5);
}

TEST(GlobalPositioning, RobustLossToleratesOutlierBearings) {
  Scene scene = RandomScene(40, 1500, 0.001, 31);
  const int num_outliers = CorruptBearings(&scene, 0.1, 32);
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, TestOptions());
  ASSERT_TRUE(result.report.success) << result.report.termination;
  const Errors errors = AlignedErrors(result, scene, Undetermined(scene));
  RecordErrors(errors);
  EXPECT_LT(errors.centre_rms, 0.01);
  EXPECT_LT(errors.point_rms, 0.01);
  ::testing::Test::RecordProperty("num_corrupted", num_outliers);
  ::testing::Test::RecordProperty("num_large_angle", result.report.num_large_angle_observations);
  // The outliers, and about only they, end with large angles.
  EXPECT_GT(result.report.num_large_angle_observations, 0.9 * num_outliers);
  EXPECT_LT(result.report.num_large_angle_observations, 1.1 * num_outliers);
}


TEST(GlobalPositioning, IterativeSchurWithCauchyLossRecoversScene) {
  Scene scene = RandomScene(20, 500, 0.001, 35);
  CorruptBearings(&scene, 0.05, 36);
  GlobalPositioningOptions options = TestOptions();
  options.linear_solver = PositioningLinearSolver::kIterativeSchur;
  options.loss = PositioningLoss::kCauchy;
  options.loss_scale = 0.05;
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, options);
  ASSERT_TRUE(result.report.success) << result.report.termination;
  const Errors errors = AlignedErrors(result, scene, Undetermined(scene));
  RecordErrors(errors);
  EXPECT_LT(errors.centre_rms, 0.01);
  EXPECT_LT(errors.point_rms, 0.01);
}

// fox's failure in small: a video whose first frames move slowly and the rest fast, the two
// parts tied only by the tracks across the change, 10 % of the bearings wrong, from the
// chained start. Under the default Cauchy loss both parts keep one scale; under Huber's
// linear tail the wrong bearings among the few tying tracks set the parts' relative scale.
// Measured when written, the first part's scale over the rest's, seeds 1 to 7: Cauchy 0.995,
// 1.199, 0.998, 0.996, 1.073, 0.997, 1.005; Huber (scale 0.1) 1.85, 1.59, 2.27, 1.14, 1.84,
// 0.76, 1.30.
TEST(GlobalPositioning, CauchyLossKeepsOneScaleForLooselyTiedParts) {
  std::vector<double> deviations;
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    Scene scene = TwoPaceOrbitScene(9, 0.1, 50, 0.6, 12, 0.001, seed);
    CorruptBearings(&scene, 0.1, 10 + seed);
    const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, TestOptions());
    ASSERT_TRUE(result.report.success) << result.report.termination;
    const double relative = PathScale(result, scene, 0, 8) / PathScale(result, scene, 9, 58);
    ::testing::Test::RecordProperty("relative_scale_seed_" + std::to_string(seed),
                                    std::to_string(relative));
    deviations.push_back(std::abs(relative - 1.0));
  }
  std::sort(deviations.begin(), deviations.end());
  EXPECT_LT(deviations[deviations.size() / 2], 0.05);
  EXPECT_LT(deviations.back(), 0.5);
}

TEST(GlobalPositioning, ExactDataAtTheTruthIsAFixedPoint) {
  Scene scene = RandomScene(12, 200, 0.0, 41);
  scene.input.initial_centres = scene.true_centres;
  for (const BearingObservation& obs : scene.input.observations) {
    scene.input.initial_points[obs.point_id] = scene.true_points.at(obs.point_id);
  }
  GlobalPositioningOptions options = TestOptions();
  options.normalize_gauge = false;
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, options);
  ASSERT_TRUE(result.report.success) << result.report.termination;
  EXPECT_LT(result.report.final_cost, 1e-16);
  for (const auto& [id, centre] : result.camera_centres) {
    EXPECT_LT((centre - scene.true_centres.at(id)).norm(), 1e-6) << "image " << id;
  }
  for (const auto& [id, point] : result.points) {
    EXPECT_LT((point - scene.true_points.at(id)).norm(), 1e-6) << "point " << id;
  }
  for (double angle : result.observation_angles) {
    if (std::isnan(angle)) continue;
    EXPECT_LT(angle, 1e-6);
  }
}

TEST(GlobalPositioning, PosesFromCentresMapTheCentreToTheOrigin) {
  const Scene scene = RandomScene(5, 10, 0.0, 51);
  const auto poses =
      CamFromWorldFromCentres(scene.input.cam_from_world_rotations, scene.true_centres);
  ASSERT_EQ(poses.size(), scene.true_centres.size());
  for (const auto& [id, pose] : poses) {
    EXPECT_LT((pose * scene.true_centres.at(id)).norm(), 1e-9);
    EXPECT_LT(pose.rotation.angularDistance(scene.input.cam_from_world_rotations.at(id)), 1e-12);
    // A point in front of the camera in the world is in front of it in the camera frame.
    for (const BearingObservation& obs : scene.input.observations) {
      if (obs.image_id != id) continue;
      const Eigen::Vector3d in_cam = pose * scene.true_points.at(obs.point_id);
      EXPECT_LT((in_cam.normalized() - obs.bearing_in_cam).norm(), 1e-9);
    }
  }
}

TEST(GlobalPositioning, CameraDirectionsAlonePositionCameras) {
  Scene scene = RandomScene(15, 0, 0.0, 61);
  for (auto i = scene.true_centres.begin(); i != scene.true_centres.end(); ++i) {
    for (auto j = std::next(i); j != scene.true_centres.end(); ++j) {
      scene.input.camera_directions.push_back({i->first, j->first, j->second - i->second});
    }
  }
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, TestOptions());
  ASSERT_TRUE(result.report.success) << result.report.termination;
  EXPECT_EQ(result.report.num_cameras, 15);
  EXPECT_EQ(result.report.num_camera_directions, 15 * 14 / 2);
  const Errors errors = AlignedErrors(result, scene);
  EXPECT_LT(errors.centre_rms, 1e-4);
}

TEST(GlobalPositioning, NormalizedGaugeHasZeroMeanAndUnitSpread) {
  const Scene scene = RandomScene(20, 300, 0.001, 71);
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, TestOptions());
  ASSERT_TRUE(result.report.success);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& [id, centre] : result.camera_centres) mean += centre;
  mean /= result.camera_centres.size();
  double squared = 0.0;
  for (const auto& [id, centre] : result.camera_centres) squared += centre.squaredNorm();
  EXPECT_LT(mean.norm(), 1e-9);
  EXPECT_NEAR(std::sqrt(squared / result.camera_centres.size()), 1.0, 1e-9);
}

TEST(GlobalPositioning, SeedDecidesTheRandomStart) {
  const Scene scene = RandomScene(10, 100, 0.001, 81);
  GlobalPositioningOptions options = TestOptions();
  options.max_num_iterations = 1;
  const double a = SolveGlobalPositioning(scene.input, options).report.initial_cost;
  const double b = SolveGlobalPositioning(scene.input, options).report.initial_cost;
  options.seed += 1;
  const double c = SolveGlobalPositioning(scene.input, options).report.initial_cost;
  EXPECT_NEAR(a, b, 1e-9 * a);
  EXPECT_GT(std::abs(a - c), 1e-6 * a);
}

TEST(GlobalPositioning, PointsWithTooFewViewsAreLeftOut) {
  Scene scene = RandomScene(10, 50, 0.0, 91);
  // Keep only the first observation of every point.
  std::vector<BearingObservation> once;
  std::map<point3D_t, bool> seen;
  for (const BearingObservation& obs : scene.input.observations) {
    if (seen[obs.point_id]) continue;
    seen[obs.point_id] = true;
    once.push_back(obs);
  }
  scene.input.observations = once;
  const GlobalPositioningResult result = SolveGlobalPositioning(scene.input, TestOptions());
  EXPECT_FALSE(result.report.success);
  EXPECT_EQ(result.report.num_skipped_points, static_cast<int>(once.size()));
  EXPECT_TRUE(result.points.empty());
  EXPECT_TRUE(result.camera_centres.empty());
  ASSERT_EQ(result.observation_angles.size(), once.size());
  EXPECT_TRUE(std::isnan(result.observation_angles[0]));
}

TEST(GlobalPositioning, BadOptionsThrow) {
  const auto throws = [](auto change) {
    GlobalPositioningOptions options;
    change(options);
    EXPECT_THROW(options.Check(), InvalidArgument);
  };
  EXPECT_NO_THROW(GlobalPositioningOptions().Check());
  throws([](GlobalPositioningOptions& o) { o.loss_scale = 0.0; });
  throws([](GlobalPositioningOptions& o) { o.loss_scale = std::nan(""); });
  throws([](GlobalPositioningOptions& o) { o.random_init_extent = -1.0; });
  throws([](GlobalPositioningOptions& o) { o.min_scale = -1e-3; });
  throws([](GlobalPositioningOptions& o) { o.min_num_views_per_point = 0; });
  throws([](GlobalPositioningOptions& o) { o.camera_direction_weight = 0.0; });
  throws([](GlobalPositioningOptions& o) { o.max_angle_error_deg = 0.0; });
  throws([](GlobalPositioningOptions& o) { o.max_num_iterations = 0; });
  throws([](GlobalPositioningOptions& o) { o.function_tolerance = -1.0; });
  GlobalPositioningOptions bad;
  bad.max_num_iterations = -3;
  EXPECT_THROW(SolveGlobalPositioning(RandomScene(3, 10, 0.0, 1).input, bad), InvalidArgument);
}

TEST(GlobalPositioning, EmptyOrInconsistentInputThrows) {
  const Scene scene = RandomScene(4, 30, 0.0, 101);
  ASSERT_FALSE(scene.input.observations.empty());
  const auto throws = [&](auto change) {
    GlobalPositioningInput input = scene.input;
    change(input);
    EXPECT_THROW(SolveGlobalPositioning(input, TestOptions()), InvalidArgument);
  };
  throws([](GlobalPositioningInput& in) { in.observations.clear(); });
  throws([](GlobalPositioningInput& in) { in.observations[0].image_id = 999; });
  throws([](GlobalPositioningInput& in) { in.observations[0].bearing_in_cam.setZero(); });
  throws([](GlobalPositioningInput& in) { in.observations[0].bearing_in_cam.x() = NAN; });
  throws([](GlobalPositioningInput& in) {
    in.cam_from_world_rotations.begin()->second.coeffs().setZero();
  });
  throws([](GlobalPositioningInput& in) { in.initial_centres[999] = Eigen::Vector3d::Zero(); });
  throws([](GlobalPositioningInput& in) { in.initial_points[999999] = Eigen::Vector3d::Zero(); });
  throws([](GlobalPositioningInput& in) {
    const image_t id = in.cam_from_world_rotations.begin()->first;
    in.camera_directions.push_back({id, id, Eigen::Vector3d::UnitX()});
  });
  throws([](GlobalPositioningInput& in) {
    const image_t id = in.cam_from_world_rotations.begin()->first;
    in.camera_directions.push_back({id, 999, Eigen::Vector3d::UnitX()});
  });
  EXPECT_NO_THROW(SolveGlobalPositioning(scene.input, TestOptions()));
}

}  // namespace
}  // namespace loopsfm
