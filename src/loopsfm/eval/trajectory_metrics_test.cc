#include "loopsfm/eval/trajectory_metrics.h"

#include <gtest/gtest.h>

#include <Eigen/QR>
#include <cmath>

#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

std::string FrameName(int i, const char* extension = ".png") {
  return fmt::format("frame_{:06d}{}", i, extension);
}

// A closed loop of radius 10 with some height variation; cameras look at the centre.
std::vector<TrajectoryEntry> LoopTrajectory(int num_frames) {
  std::vector<TrajectoryEntry> entries;
  for (int i = 0; i < num_frames; ++i) {
    const double a = 2.0 * M_PI * i / num_frames;
    const Eigen::Vector3d centre(10 * std::cos(a), 10 * std::sin(a), 1.5 * std::sin(3 * a));
    const Eigen::Quaterniond world_from_cam_rotation(
        Eigen::AngleAxisd(a + M_PI / 2, Eigen::Vector3d::UnitZ()) *
        Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()) *
        Eigen::AngleAxisd(0.1 * std::sin(a), Eigen::Vector3d::UnitY()));
    entries.push_back({FrameName(i), Rigid3d(world_from_cam_rotation, centre)});
  }
  return entries;
}

Sim3d RandomSim3(Random& random) {
  Sim3d sim;
  sim.scale = random.UniformReal(0.2, 5.0);
  sim.rotation =
      Eigen::Quaterniond(random.Normal(), random.Normal(), random.Normal(), random.Normal())
          .normalized();
  sim.translation =
      Eigen::Vector3d(random.Normal(0, 20), random.Normal(0, 20), random.Normal(0, 20));
  return sim;
}

// A pose moved into another world by a similarity (centre by Sim3, orientation by rotation).
Rigid3d Transform(const Sim3d& b_from_a, const Rigid3d& world_a_from_cam) {
  return Rigid3d(b_from_a.rotation * world_a_from_cam.rotation,
                 b_from_a * world_a_from_cam.translation);
}

// Noise on the centres that is zero-mean and uncorrelated with the centred positions
// (each coordinate orthogonal to 1 and to the three centred coordinate columns), so the
// Umeyama rotation is exactly the true one and the ATE has a closed form.
std::vector<Eigen::Vector3d> UncorrelatedNoise(const std::vector<TrajectoryEntry>& gt, double sigma,
                                               Random& random) {
  const int n = static_cast<int>(gt.size());
  Eigen::MatrixXd basis(n, 4);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& e : gt) mean += e.world_from_cam.translation / n;
  for (int i = 0; i < n; ++i) {
    basis(i, 0) = 1.0;
    basis.block<1, 3>(i, 1) = (gt[i].world_from_cam.translation - mean).transpose();
  }
  const Eigen::MatrixXd q =
      Eigen::HouseholderQR<Eigen::MatrixXd>(basis).householderQ() * Eigen::MatrixXd::Identity(n, 4);
  Eigen::MatrixXd noise(n, 3);
  for (int k = 0; k < 3; ++k) {
    Eigen::VectorXd r(n);
    for (int i = 0; i < n; ++i) r(i) = random.Normal(0, sigma);
    noise.col(k) = r - q * (q.transpose() * r);
  }
  std::vector<Eigen::Vector3d> result(n);
  for (int i = 0; i < n; ++i) result[i] = noise.row(i).transpose();
  return result;
}

TEST(TrajectoryMetrics, PerfectTrajectoryUnderRandomSim3HasZeroError) {
  Random random(7);
  const auto gt = LoopTrajectory(40);
  for (int trial = 0; trial < 5; ++trial) {
    const Sim3d est_from_gt = RandomSim3(random);
    std::vector<TrajectoryEntry> estimated;
    for (const auto& e : gt)
      estimated.push_back({e.name, Transform(est_from_gt, e.world_from_cam)});
    const TrajectoryMetrics m = EvaluateTrajectory(estimated, gt);
    ASSERT_TRUE(m.aligned) << m.explanation;
    EXPECT_EQ(m.num_matched, 40u);
    EXPECT_DOUBLE_EQ(m.fraction_registered, 1.0);
    EXPECT_LT(m.ate_rmse, 1e-9);
    EXPECT_LT(m.rotation_error_max_deg, 1e-6);
    EXPECT_NEAR(m.gt_from_estimated.scale * est_from_gt.scale, 1.0, 1e-12);
    ASSERT_TRUE(m.rpe.has_value());
    EXPECT_EQ(m.rpe->num_pairs, 39u);
    EXPECT_LT(m.rpe->translation_max, 1e-9);
    EXPECT_LT(m.rpe->rotation_max_deg, 1e-6);
  }
}

TEST(TrajectoryMetrics, KnownNoiseGivesExpectedErrors) {
  Random random(11);
  const auto gt = LoopTrajectory(60);
  const double sigma = 0.05;
  const auto noise = UncorrelatedNoise(gt, sigma, random);
  const Sim3d est_from_gt = RandomSim3(random);
  std::vector<TrajectoryEntry> estimated;
  std::vector<double> angles_deg;
  for (size_t i = 0; i < gt.size(); ++i) {
    // Orientation noise of a known angle about a random axis.
    const double angle_deg = 0.5 + 0.01 * i;
    angles_deg.push_back(angle_deg);
    const Eigen::Vector3d axis =
        Eigen::Vector3d(random.Normal(), random.Normal(), random.Normal()).normalized();
    const Rigid3d noisy(gt[i].world_from_cam.rotation *
                            Eigen::Quaterniond(Eigen::AngleAxisd(angle_deg * M_PI / 180, axis)),
                        gt[i].world_from_cam.translation + noise[i]);
    estimated.push_back({gt[i].name, Transform(est_from_gt, noisy)});
  }
  // Optimal scale of (x + e) onto x with e uncorrelated: c = A / (A + E), residual AE/(A+E).
  double a = 0, e = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& entry : gt) mean += entry.world_from_cam.translation / gt.size();
  for (size_t i = 0; i < gt.size(); ++i) {
    a += (gt[i].world_from_cam.translation - mean).squaredNorm();
    e += noise[i].squaredNorm();
  }
  const double expected_ate = std::sqrt(a * e / (a + e) / gt.size());
  const double c = a / (a + e);

  const TrajectoryMetrics m = EvaluateTrajectory(estimated, gt);
  ASSERT_TRUE(m.aligned) << m.explanation;
  EXPECT_NEAR(m.ate_rmse, expected_ate, 1e-9);
  EXPECT_NEAR(m.ate_rmse, sigma * std::sqrt(3.0), 0.3 * sigma * std::sqrt(3.0));
  EXPECT_NEAR(m.gt_from_estimated.scale * est_from_gt.scale, c, 1e-9);
  EXPECT_NEAR(m.ate_fraction_of_path, m.ate_rmse / m.gt_path_length, 1e-15);
  EXPECT_NEAR(m.rotation_error_mean_deg, 0.5 + 0.01 * 59 / 2, 1e-7);
  EXPECT_NEAR(m.rotation_error_median_deg, 0.5 + 0.01 * 29.5, 1e-7);
  EXPECT_NEAR(m.rotation_error_max_deg, 0.5 + 0.01 * 59, 1e-7);
  ASSERT_EQ(m.frames.size(), gt.size());
  for (size_t i = 0; i < gt.size(); ++i) {
    EXPECT_NEAR(m.frames[i].rotation_error_deg, angles_deg[i], 1e-7);
    const Eigen::Vector3d x = gt[i].world_from_cam.translation - mean;
    EXPECT_NEAR(m.frames[i].position_error, ((1 - c) * x - c * noise[i]).norm(), 1e-9);
  }
}

TEST(TrajectoryMetrics, RelativePoseErrorMatchesCentreDifferences) {
  Random random(3);
  const auto gt = LoopTrajectory(30);
  const auto noise = UncorrelatedNoise(gt, 0.02, random);
  std::vector<TrajectoryEntry> estimated;
  for (size_t i = 0; i < gt.size(); ++i) {
    estimated.push_back({gt[i].name, Rigid3d(gt[i].world_from_cam.rotation,
                                             gt[i].world_from_cam.translation + noise[i])});
  }
  TrajectoryEvalOptions options;
  options.rpe_step = 2;
  const TrajectoryMetrics m = EvaluateTrajectory(estimated, gt, options);
  ASSERT_TRUE(m.aligned && m.rpe.has_value());
  const double c = m.gt_from_estimated.scale;
  double sum = 0;
  for (size_t k = 0; k + 2 < gt.size(); ++k) {
    const Eigen::Vector3d gt_step =
        gt[k + 2].world_from_cam.translation - gt[k].world_from_cam.translation;
    sum += (c * (gt_step + noise[k + 2] - noise[k]) - gt_step).squaredNorm();
  }
  EXPECT_EQ(m.rpe->step, 2);
  EXPECT_EQ(m.rpe->num_pairs, 28u);
  EXPECT_NEAR(m.rpe->translation_rmse, std::sqrt(sum / 28), 1e-9);
  EXPECT_LT(m.rpe->rotation_max_deg, 1e-6);
}

TEST(TrajectoryMetrics, MissingAndExtraFramesAreCounted) {
  const auto gt = LoopTrajectory(50);
  std::vector<TrajectoryEntry> estimated;
  for (size_t i = 0; i < gt.size(); ++i) {
    if (i % 5 == 0) continue;  // 10 missing
    estimated.push_back(gt[i]);
  }
  estimated.push_back({"not_in_gt.png", Rigid3d()});
  const TrajectoryMetrics m = EvaluateTrajectory(estimated, gt);
  EXPECT_EQ(m.num_gt_frames, 50u);
  EXPECT_EQ(m.num_estimated, 41u);
  EXPECT_EQ(m.num_matched, 40u);
  EXPECT_DOUBLE_EQ(m.fraction_registered, 0.8);
  EXPECT_LT(m.ate_rmse, 1e-9);
  ASSERT_TRUE(m.rpe.has_value());
  // Pairs (k, k+1) with neither index a multiple of 5: 49 pairs minus 2 per missing frame
  // (frame 0 only breaks one pair).
  EXPECT_EQ(m.rpe->num_pairs, 49u - 19u);
  EXPECT_EQ(m.frames.front().gt_index, 1u);
}

TEST(TrajectoryMetrics, PathLengthCoversAllGroundTruthFrames) {
  std::vector<TrajectoryEntry> gt;
  const std::vector<Eigen::Vector3d> corners = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0},
                                                {0, 2, 0}, {0, 2, 3}, {0, 0, 3}};
  for (size_t i = 0; i < corners.size(); ++i)
    gt.push_back({FrameName(i), Rigid3d(Eigen::Quaterniond::Identity(), corners[i])});
  EXPECT_DOUBLE_EQ(TrajectoryPathLength(gt), 2 + 2 + 2 + 3 + 2);
  // Only frames 1..4 estimated; the path length still uses all six.
  std::vector<TrajectoryEntry> estimated(gt.begin() + 1, gt.begin() + 5);
  const TrajectoryMetrics m = EvaluateTrajectory(estimated, gt);
  EXPECT_DOUBLE_EQ(m.gt_path_length, 11.0);
  EXPECT_EQ(m.num_matched, 4u);
  EXPECT_TRUE(m.aligned);
}

TEST(TrajectoryMetrics, FewerThanThreeMatchesIsExplainedNotFatal) {
  const auto gt = LoopTrajectory(10);
  const std::vector<TrajectoryEntry> estimated = {gt[0], gt[3], {"other.png", Rigid3d()}};
  const TrajectoryMetrics m = EvaluateTrajectory(estimated, gt);
  EXPECT_FALSE(m.aligned);
  EXPECT_EQ(m.num_matched, 2u);
  EXPECT_DOUBLE_EQ(m.fraction_registered, 0.2);
  EXPECT_NE(m.explanation.find("only 2 of 3"), std::string::npos) << m.explanation;
  EXPECT_TRUE(std::isnan(m.ate_rmse));
  EXPECT_TRUE(std::isnan(m.rotation_error_mean_deg));
  EXPECT_FALSE(m.rpe.has_value());
  EXPECT_EQ(m.frames.size(), 2u);
  const nlohmann::json json = ToJson(m);
  EXPECT_TRUE(json["ate_rmse"].is_null());
  EXPECT_FALSE(json["aligned"].get<bool>());
  EXPECT_NE(json.dump().find("only 2 of 3"), std::string::npos);

  const TrajectoryMetrics empty = EvaluateTrajectory(std::vector<TrajectoryEntry>{}, {});
  EXPECT_FALSE(empty.aligned);
  EXPECT_EQ(empty.fraction_registered, 0.0);
  EXPECT_EQ(empty.gt_path_length, 0.0);
}

TEST(TrajectoryMetrics, CollinearCentresAreExplained) {
  std::vector<TrajectoryEntry> gt;
  for (int i = 0; i < 6; ++i)
    gt.push_back({FrameName(i), Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(i, 0, 0))});
  const TrajectoryMetrics m = EvaluateTrajectory(gt, gt);
  EXPECT_FALSE(m.aligned);
  EXPECT_EQ(m.num_matched, 6u);
  EXPECT_NE(m.explanation.find("one line"), std::string::npos) << m.explanation;
  EXPECT_DOUBLE_EQ(m.gt_path_length, 5.0);
}

// A straight walk with a few centimetres of shake across it, estimated with a lateral error
// ten times larger: the centres barely fix the alignment's roll about the walk, and the
// metrics say so. The same error on a loop leaves the roll well fixed.
TEST(TrajectoryMetrics, RollUncertaintyIsLargeWhereCentresAreNearlyOnALine) {
  auto with_error = [](const std::vector<TrajectoryEntry>& gt) {
    std::vector<TrajectoryEntry> estimated = gt;
    for (size_t i = 0; i < gt.size(); ++i) {
      const double t = 2.0 * M_PI * i / gt.size();
      estimated[i].world_from_cam.translation += Eigen::Vector3d(0, 0.3 * std::sin(t), 0.2 * std::cos(2 * t));
    }
    return estimated;
  };
  std::vector<TrajectoryEntry> line;
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d centre(i, 0.03 * std::sin(0.7 * i), 0.02 * std::cos(1.3 * i));
    line.push_back({FrameName(i), Rigid3d(Eigen::Quaterniond::Identity(), centre)});
  }
  const TrajectoryMetrics straight = EvaluateTrajectory(with_error(line), line);
  ASSERT_TRUE(straight.aligned) << straight.explanation;
  const std::vector<TrajectoryEntry> loop = LoopTrajectory(200);
  const TrajectoryMetrics round = EvaluateTrajectory(with_error(loop), loop);
  ASSERT_TRUE(round.aligned) << round.explanation;
  EXPECT_GT(straight.alignment_roll_uncertainty_deg, 10 * round.alignment_roll_uncertainty_deg)
      << straight.alignment_roll_uncertainty_deg;
  EXPECT_LT(round.alignment_roll_uncertainty_deg, 0.2);
  // The RMS error across the walk over the root of the centres' summed squared distances
  // from it (the walk's main axis is x to within the shake).
  double off_axis = 0.0, across = 0.0;
  for (size_t i = 0; i < line.size(); ++i) {
    const Eigen::Vector3d c = line[i].world_from_cam.translation;
    off_axis += std::pow(c.y(), 2) + std::pow(c.z(), 2);
    const Eigen::Vector3d e = straight.frames[i].aligned_centre - c;
    across += std::pow(e.y(), 2) + std::pow(e.z(), 2);
  }
  EXPECT_NEAR(straight.alignment_roll_uncertainty_deg,
              std::atan(std::sqrt(across / line.size() / off_axis)) * 180.0 / M_PI,
              0.02 * straight.alignment_roll_uncertainty_deg);
  EXPECT_TRUE(ToJson(straight, false).contains("alignment_roll_uncertainty_deg"));
}

TEST(TrajectoryMetrics, NamesJoinExactlyFirstThenWithoutExtension) {
  EXPECT_EQ(TrajectoryNameKey("images/frame_000001.jpg"), "frame_000001");
  EXPECT_EQ(TrajectoryNameKey("frame_000001"), "frame_000001");
  EXPECT_EQ(TrajectoryNameKey("dir.v2/frame"), "frame");
  EXPECT_EQ(TrajectoryNameKey(".hidden"), ".hidden");

  std::vector<TrajectoryEntry> gt = {
      {"a.png", {}}, {"b.png", {}}, {"c.png", {}}, {"d.png", {}}, {"e.png", {}}};
  std::vector<TrajectoryEntry> estimated = {
      {"a.jpg", {}}, {"a.png", {}},      // exact match wins over the key match
      {"b.jpg", {}},                     // joined by key
      {"c.jpg", {}}, {"sub/c.tif", {}},  // ambiguous key: not joined
      {"e", {}}};                        // joined by key
  const auto matches = JoinTrajectoriesByName(estimated, gt, true);
  ASSERT_EQ(matches.size(), 3u);
  EXPECT_EQ(matches[0].gt_index, 0u);
  EXPECT_EQ(matches[0].estimated_index, 1u);
  EXPECT_EQ(matches[1].gt_index, 1u);
  EXPECT_EQ(matches[1].estimated_index, 2u);
  EXPECT_EQ(matches[2].gt_index, 4u);
  EXPECT_EQ(matches[2].estimated_index, 5u);
  EXPECT_EQ(JoinTrajectoriesByName(estimated, gt, false).size(), 1u);
}

TEST(TrajectoryMetrics, ReadsRegisteredImagesOfReconstruction) {
  const auto gt = LoopTrajectory(8);
  Reconstruction rec;
  Camera camera = Camera::GuessFromImageSize(640, 480);
  camera.camera_id = 1;
  rec.AddCamera(camera);
  // Added in reverse name order; image 8 stays unregistered.
  for (int i = 0; i < 9; ++i) {
    Image image;
    image.image_id = i + 1;
    image.camera_id = 1;
    image.name = FrameName(8 - i, ".jpg");
    if (i > 0) image.cam_from_world = gt[8 - i].world_from_cam.Inverse();
    rec.AddImage(image);
    if (i > 0) rec.RegisterImage(i + 1);
  }
  const auto trajectory = TrajectoryFromReconstruction(rec);
  ASSERT_EQ(trajectory.size(), 8u);
  EXPECT_EQ(trajectory.front().name, FrameName(0, ".jpg"));
  EXPECT_LT((trajectory[3].world_from_cam.translation - gt[3].world_from_cam.translation).norm(),
            1e-12);
  const TrajectoryMetrics m = EvaluateTrajectory(rec, gt);
  EXPECT_EQ(m.num_matched, 8u);
  EXPECT_LT(m.ate_rmse, 1e-9);
}

TEST(TrajectoryMetrics, JsonHoldsMetricsAndFrames) {
  const auto gt = LoopTrajectory(12);
  const TrajectoryMetrics m = EvaluateTrajectory(gt, gt);
  const nlohmann::json json = ToJson(m);
  EXPECT_EQ(json["num_matched"].get<size_t>(), 12u);
  EXPECT_NEAR(json["gt_path_length"].get<double>(), m.gt_path_length, 1e-12);
  EXPECT_NEAR(json["gt_from_estimated"]["scale"].get<double>(), 1.0, 1e-9);
  EXPECT_EQ(json["frames"].size(), 12u);
  EXPECT_EQ(json["frames"][3]["gt_name"].get<std::string>(), FrameName(3));
  EXPECT_EQ(json["rpe"]["num_pairs"].get<size_t>(), 11u);
  EXPECT_FALSE(ToJson(m, false).contains("frames"));
  // Round trip through text.
  EXPECT_EQ(nlohmann::json::parse(json.dump()), json);
}

// 1.2 laps of a circle with 100 frames a lap: frames 100-119 revisit frames 0-19.
std::vector<TrajectoryEntry> LapAndAFifth() {
  std::vector<TrajectoryEntry> entries = LoopTrajectory(100);
  for (int i = 100; i < 120; ++i) {
    entries.push_back({FrameName(i), entries[i - 100].world_from_cam});
  }
  return entries;
}

TEST(TrajectoryMetrics, LoopGapIsZeroForAClosedLoopAndAbsentWithoutRevisits) {
  const auto gt = LapAndAFifth();
  // Half a step: only the exact revisits count (frames 20-22 are also within three steps
  // of frame 119).
  TrajectoryEvalOptions options;
  options.loop_max_distance_steps = 0.5;
  TrajectoryMetrics m = EvaluateTrajectory(gt, gt, options);
  ASSERT_TRUE(m.loop_gaps.has_value());
  EXPECT_EQ(m.loop_gaps->min_frame_gap, 24);  // a fifth of 120 frames
  EXPECT_EQ(m.loop_gaps->num_revisits, 20u);
  EXPECT_LT(m.loop_gaps->max, 1e-9);

  // Half a lap never comes back.
  const auto half = LoopTrajectory(200);
  const std::vector<TrajectoryEntry> open(half.begin(), half.begin() + 100);
  m = EvaluateTrajectory(open, open, options);
  ASSERT_TRUE(m.loop_gaps.has_value());
  EXPECT_EQ(m.loop_gaps->num_revisits, 0u);
  EXPECT_TRUE(std::isnan(m.loop_gaps->max));
}

TEST(TrajectoryMetrics, LoopGapMeasuresHowFarTheSecondPassIsOff) {
  const auto gt = LapAndAFifth();
  // The second pass is shifted by 0.2 (2 % of the radius), as if drift went unclosed; the
  // first lap is exact. The ATE spreads the shift over all frames, the loop gap does not.
  const Eigen::Vector3d shift(0.12, -0.16, 0.0);
  std::vector<TrajectoryEntry> estimated = gt;
  for (int i = 100; i < 120; ++i) estimated[i].world_from_cam.translation += shift;
  TrajectoryEvalOptions options;
  options.loop_max_distance_steps = 0.5;
  const TrajectoryMetrics m = EvaluateTrajectory(estimated, gt, options);
  ASSERT_TRUE(m.loop_gaps.has_value());
  EXPECT_EQ(m.loop_gaps->num_revisits, 20u);
  EXPECT_NEAR(m.loop_gaps->median, 0.2, 0.02);
  EXPECT_NEAR(m.loop_gaps->max, 0.2, 0.02);
  EXPECT_LT(m.ate_rmse, 0.5 * m.loop_gaps->median);
  const nlohmann::json json = ToJson(m, false);
  EXPECT_EQ(json["loop_gaps"]["num_revisits"].get<size_t>(), 20u);
}

TEST(TrajectoryMetrics, APlacePassedLookingTheOtherWayIsNoRevisit) {
  // The extra fifth of a lap walks past the first frames' places turned by 120 degrees
  // (a figure-eight's crossing, the other side of a street): it does not see them again.
  std::vector<TrajectoryEntry> gt = LapAndAFifth();
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(2.0 * M_PI / 3.0, Eigen::Vector3d::UnitY()));
  for (int i = 100; i < 120; ++i) gt[i].world_from_cam.rotation = gt[i].world_from_cam.rotation * turn;
  TrajectoryEvalOptions options;
  options.loop_max_distance_steps = 0.5;
  TrajectoryMetrics m = EvaluateTrajectory(gt, gt, options);
  ASSERT_TRUE(m.loop_gaps.has_value());
  EXPECT_EQ(m.loop_gaps->num_revisits, 0u);
  // Within the angle they count again.
  options.loop_max_view_angle_deg = 150.0;
  m = EvaluateTrajectory(gt, gt, options);
  EXPECT_EQ(m.loop_gaps->num_revisits, 20u);
}

TEST(TrajectoryMetrics, OptionsAreChecked) {
  TrajectoryEvalOptions options;
  options.rpe_step = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.min_matched_frames = 2;
  EXPECT_THROW(EvaluateTrajectory(std::vector<TrajectoryEntry>{}, {}, options), InvalidArgument);
  options = {};
  options.loop_max_distance_steps = 0.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.loop_max_view_angle_deg = 0.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
