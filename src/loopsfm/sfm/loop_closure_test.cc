#include "loopsfm/sfm/loop_closure.h"

#include <algorithm>
#include <map>
#include <unordered_set>
#include <vector>

#include <gtest/gtest.h>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/loop_test_problem.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using testing::MapperProblem;
using testing::RegisterTurnedAndScaled;
using testing::RegisterWithDrift;
using testing::WalkOutAndBack;

IncrementalMapperOptions LoopOptions() {
  IncrementalMapperOptions options;
  options.loop_closure.min_frame_gap = 20;
  options.num_threads = 1;
  return options;
}

// Offers the last frames to the loop closer as if they had just been registered.
MapperReport OfferLastFrames(const MapperProblem& p, MapperState& state, int count) {
  MapperReport report;
  LoopCloser closer(p.input, state.options().loop_closure, 5);
  const size_t n = p.input.frames.size();
  for (size_t i = n - count; i < n; ++i) {
    closer.AfterRegistration(state, p.input.frames[i].image_id, &report);
  }
  return report;
}

// The walk out and back registered with drift: 1.5 cm a frame, 0.6 m at the end of the walk
// back, 30-40 px against the first frames.
struct DriftedWalk {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state{p.input, options};
  testing::PoseError before;
  size_t points_before = 0;
  DriftedWalk() {
    RegisterWithDrift(p, state, 0.015);
    before = testing::ComparePoses(state.reconstruction(), p);
    points_before = state.reconstruction().NumPoints3D();
  }
};

TEST(LoopCloser, DriftedWalkBackIsClosedAndItsEndsFused) {
  DriftedWalk walk;
  const MapperProblem& p = walk.p;
  const IncrementalMapperOptions& options = walk.options;
  MapperState& state = walk.state;
  const testing::PoseError& before = walk.before;
  const size_t points_before = walk.points_before;

  const MapperReport report = OfferLastFrames(p, state, 10);
  ASSERT_EQ(report.loops_closed.size(), 1u);
  const ClosedLoop& loop = report.loops_closed[0];
  EXPECT_GE(loop.num_inliers, options.loop_closure.min_num_inliers);
  EXPECT_GT(loop.correction_translation, 0.2);
  const testing::PoseError after = testing::ComparePoses(state.reconstruction(), p);
  EXPECT_EQ(after.num_registered, 80);
  EXPECT_LT(after.max_centre_error, 0.25 * before.max_centre_error)
      << "before " << before.max_centre_error << ", after " << after.max_centre_error;
  // The two ends' points of one track were fused.
  EXPECT_LT(state.reconstruction().NumPoints3D(), 0.9 * points_before);
  // One link per loop edge, from the walk out to the walk back, carrying the inlier pairs.
  testing::ExpectLinksAcrossTheLoop(p, report, "posegraph", options.loop_closure.min_frame_gap,
                                    loop.num_inliers);
}

// Drift with a turn and a change of scale (a focal length a few percent off does this over a
// lap, as on drift2): the pose graph's correction turns and scales the walk back, and the
// ends' points are fused.
TEST(LoopCloser, TurnedAndScaledWalkBackIsClosedAndItsEndsFused) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state(p.input, options);
  RegisterTurnedAndScaled(p, state);
  const testing::PoseError before = testing::ComparePoses(state.reconstruction(), p);
  const size_t points_before = state.reconstruction().NumPoints3D();

  const MapperReport report = OfferLastFrames(p, state, 10);
  ASSERT_EQ(report.loops_closed.size(), 1u);
  EXPECT_GT(report.loops_closed[0].correction_rotation_deg, 3.0);
  const testing::PoseError after = testing::ComparePoses(state.reconstruction(), p);
  EXPECT_EQ(after.num_registered, 80);
  EXPECT_LT(after.max_centre_error, 0.25 * before.max_centre_error)
      << "before " << before.max_centre_error << ", after " << after.max_centre_error;
  EXPECT_LT(state.reconstruction().NumPoints3D(), 0.9 * points_before);
}

// After mapping (no refinement per loop), every window of the overlap is gathered and the
// loops are corrected together, in one pose graph, when asked.
TEST(LoopCloser, LoopsFoundAfterMappingAreCorrectedTogether) {
  DriftedWalk walk;
  const MapperProblem& p = walk.p;
  MapperState& state = walk.state;
  const testing::PoseError& before = walk.before;

  MapperReport report;
  LoopCloser closer(p.input, walk.options.loop_closure, 5, /*refine=*/false);
  const size_t n = p.input.frames.size();
  for (size_t i = n - 10; i < n; ++i) {
    EXPECT_FALSE(closer.AfterRegistration(state, p.input.frames[i].image_id, &report));
  }
  ASSERT_GE(report.loops_closed.size(), 2u);  // windows of 3 in 10 frames
  // Found, not yet corrected.
  EXPECT_EQ(testing::ComparePoses(state.reconstruction(), p).max_centre_error,
            before.max_centre_error);

  EXPECT_TRUE(closer.CloseGathered(state, &report));
  for (const ClosedLoop& loop : report.loops_closed) {
    EXPECT_EQ(loop.num_points_after, static_cast<long long>(state.reconstruction().NumPoints3D()));
  }
  // As CloseLoopsAfterMapping does.
  state.RefineAfterCorrection(&report, walk.options.loop_closure.refine_function_tolerance);
  const testing::PoseError after = testing::ComparePoses(state.reconstruction(), p);
  EXPECT_EQ(after.num_registered, 80);
  EXPECT_LT(after.max_centre_error, 0.25 * before.max_centre_error)
      << "before " << before.max_centre_error << ", after " << after.max_centre_error;
  EXPECT_LT(state.reconstruction().NumPoints3D(), 0.9 * walk.points_before);
  EXPECT_FALSE(closer.CloseGathered(state, &report)) << "nothing is left to correct";
}

TEST(LoopCloser, ConsistentMapHasNoLoopToClose) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, 0.0);
  const MapperReport report = OfferLastFrames(p, state, 10);
  EXPECT_TRUE(report.loops_closed.empty());
}

TEST(LoopCloser, CorrectionTooLargeForDriftIsRefused) {
  const MapperProblem p = WalkOutAndBack();
  IncrementalMapperOptions options = LoopOptions();
  // The same drift, but a correction must stay within 0.5 % of the path walked between the
  // two ends (a repeated facade far away would look like this).
  options.loop_closure.max_correction_fraction_of_path = 0.005;
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, 0.015);
  const MapperReport report = OfferLastFrames(p, state, 10);
  EXPECT_TRUE(report.loops_closed.empty());
  EXPECT_GE(report.num_loops_refused, 1);
}

// What makes a correction plausible as drift. Scale drift builds up along a loop: a loop's
// ends can differ in scale by far more than one lap's drift (drift2, focal -5 %: one lap
// 1.5, two laps 2.2) while the recent end barely moves (a path scaled about its start keeps
// its end near the start). Look-alike places ask for a large move instead.
TEST(LoopCloser, CorrectionOfSeveralLapsOfScaleDriftIsPlausible) {
  const MapperProblem p = WalkOutAndBack();
  MapperState state(p.input, LoopOptions());
  RegisterWithDrift(p, state, 0.0);
  const Reconstruction& rec = state.reconstruction();
  const int last = static_cast<int>(p.input.frames.size()) - 1;
  const image_t recent = p.input.frames[last].image_id;
  const Eigen::Vector3d start = rec.GetImage(p.input.frames[0].image_id).ProjectionCenter();
  auto scaled_about_start = [&](double scale) {
    Sim3d old_from_recent;
    old_from_recent.scale = scale;
    old_from_recent.translation = start - scale * start;
    return old_from_recent;
  };
  const LoopClosureOptions defaults;
  const DriftCorrection two_laps =
      MeasureCorrection(rec, p.input, scaled_about_start(1.0 / 2.2), recent, 0, last, defaults);
  EXPECT_DOUBLE_EQ(two_laps.scale, 1.0 / 2.2);
  EXPECT_LT(two_laps.fraction_of_path, 0.5 * defaults.max_correction_fraction_of_path);
  EXPECT_TRUE(two_laps.plausible);
  const DriftCorrection too_large =
      MeasureCorrection(rec, p.input, scaled_about_start(1.0 / 3.5), recent, 0, last, defaults);
  EXPECT_LT(too_large.fraction_of_path, defaults.max_correction_fraction_of_path);
  EXPECT_FALSE(too_large.plausible) << "scale 3.5 is no drift";
  LoopClosureOptions one_lap = defaults;
  one_lap.max_correction_scale = 1.5;
  EXPECT_FALSE(
      MeasureCorrection(rec, p.input, scaled_about_start(1.0 / 2.2), recent, 0, last, one_lap)
          .plausible);
  // A look-alike place: no change of scale, but the recent end moved by a fifth of the path.
  ASSERT_GT(two_laps.translation, 0.0);  // the walk back ends beside the start, not on it
  const double path = two_laps.translation / two_laps.fraction_of_path;
  Sim3d elsewhere;
  elsewhere.translation = Eigen::Vector3d(0.2 * path, 0.0, 0.0);
  const DriftCorrection look_alike =
      MeasureCorrection(rec, p.input, elsewhere, recent, 0, last, defaults);
  EXPECT_NEAR(look_alike.fraction_of_path, 0.2, 1e-9);
  EXPECT_FALSE(look_alike.plausible);
}

// How far the camera turned between a loop's ends, and when a loop's rotation is too large
// a share of it to be drift: the walk turning 3 deg per frame about its vertical axis, with
// 0.5 deg of shake about the horizontal one alternating frame to frame.
TEST(LoopCloser, CorrectionRotationIsMeasuredAgainstTheTurning) {
  const MapperProblem p = WalkOutAndBack();
  MapperState state(p.input, LoopOptions());
  RegisterWithDrift(p, state, 0.0);
  Reconstruction& rec = state.reconstruction();
  const int last = static_cast<int>(p.input.frames.size()) - 1;
  auto turn_walk = [&](double degrees_per_frame) {
    for (int i = 0; i <= last; ++i) {
      Image& image = rec.GetImage(p.input.frames[i].image_id);
      const Eigen::Vector3d centre = image.ProjectionCenter();
      const Eigen::Quaterniond world_from_cam =
          Eigen::AngleAxisd(degrees_per_frame * i * M_PI / 180.0, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd((i % 2 ? 0.5 : -0.5) * M_PI / 180.0, Eigen::Vector3d::UnitX());
      image.cam_from_world.rotation = world_from_cam.inverse();
      image.cam_from_world.translation = -(image.cam_from_world.rotation * centre);
    }
  };
  const image_t recent = p.input.frames[last].image_id;
  auto rotated = [](double degrees) {
    Sim3d old_from_recent;
    old_from_recent.rotation =
        Eigen::AngleAxisd(degrees * M_PI / 180.0, Eigen::Vector3d::UnitY());
    return old_from_recent;
  };
  const LoopClosureOptions defaults;
  turn_walk(3.0);
  // 79 steps of 3 deg; summed frame by frame, the shake would add about 13 deg (3.16 deg a step).
  const DriftCorrection focal_off = MeasureCorrection(rec, p.input, rotated(6.0), recent, 0, last, defaults);
  EXPECT_NEAR(focal_off.turning_deg, 237.0, 2.0);
  EXPECT_NEAR(focal_off.rotation_deg, 6.0, 1e-9);
  EXPECT_TRUE(focal_off.SuggestsWrongIntrinsics());
  // Two degrees over 237 are drift.
  EXPECT_FALSE(MeasureCorrection(rec, p.input, rotated(2.0), recent, 0, last, defaults)
                   .SuggestsWrongIntrinsics());
  // Six degrees where the camera hardly turned: no focal length explains that.
  turn_walk(0.5);
  const DriftCorrection straight = MeasureCorrection(rec, p.input, rotated(6.0), recent, 0, last, defaults);
  EXPECT_NEAR(straight.turning_deg, 39.5, 1.0);
  EXPECT_FALSE(straight.SuggestsWrongIntrinsics());
  // Unregistered frames are skipped, the last one included.
  rec.DeRegisterImage(recent);
  EXPECT_NEAR(MeasureCorrection(rec, p.input, rotated(6.0), p.input.frames[last - 1].image_id, 0,
                                last, defaults)
                  .turning_deg,
              39.0, 1.0);
}

// The alternate pose diagnostic: a frame at the end of the drifted walk back sees each
// track's old point (where the first frames put it) and its recent one (where the drifted
// walk back put it); registered again, one pose fits one end and a second RANSAC over the
// rest finds the other, as far away as the drift.
MapperReport RegisterLastFrameAgain(double drift_per_frame) {
  const MapperProblem p = WalkOutAndBack();
  IncrementalMapperOptions options = LoopOptions();
  options.record_alternate_poses = true;
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, drift_per_frame);
  const image_t last = p.input.frames.back().image_id;
  state.reconstruction().DeRegisterImage(last);
  MapperReport report;
  Random random(9);
  EXPECT_TRUE(state.RegisterImage(last, random, &report));
  return report;
}

TEST(AlternatePose, DriftedEndHasTwoPlausiblePoses) {
  const MapperReport report = RegisterLastFrameAgain(0.015);
  ASSERT_EQ(report.registrations.size(), 1u);
  const RegistrationRounds& r = report.registrations[0];
  EXPECT_TRUE(r.second_pose_found) << r.second_num_inliers << " of " << r.second_num_correspondences;
  // The walk back's last frame drifted by 39 x 1.5 cm along (0.3, 1, 0.5): 0.68 m.
  const double drift = 39 * 0.015 * Eigen::Vector3d(0.3, 1.0, 0.5).norm();
  EXPECT_NEAR(r.second_centre_distance, drift, 0.25 * drift);
}

TEST(AlternatePose, ConsistentMapHasOnePose) {
  const MapperReport report = RegisterLastFrameAgain(0.0);
  ASSERT_EQ(report.registrations.size(), 1u);
  EXPECT_FALSE(report.registrations[0].second_pose_found);
  EXPECT_GT(report.registrations[0].num_inliers, 0.9 * report.registrations[0].num_correspondences);
}

// The walk registered at its true poses, then every frame but the two gauge frames moved
// and turned at random, its points left where they were: a map as a pose-graph correction
// leaves it, its cameras far from the bundle's optimum.
void RegisterThenDisturb(const MapperProblem& p, MapperState& state) {
  RegisterWithDrift(p, state, 0.0);
  Random random(21);
  for (size_t i = 2; i < p.input.frames.size(); ++i) {
    Rigid3d& pose = state.reconstruction().GetImage(p.input.frames[i].image_id).cam_from_world;
    const Eigen::Vector3d axis = Eigen::Vector3d(random.Normal(), random.Normal(),
                                                 random.Normal()).normalized();
    pose.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.005, axis)) * pose.rotation;
    pose.translation += 0.03 * Eigen::Vector3d(random.Normal(), random.Normal(),
                                               random.Normal());
  }
}

TEST(MapperState, SubsetBundleTakesTheLongestWellTriangulatedTracksOfEveryFrame) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, 0.0);
  const Reconstruction& rec = state.reconstruction();
  const int per_frame = 40;
  const std::unordered_set<point3D_t> subset = state.LongestTrackPoints(per_frame);
  ASSERT_LT(subset.size(), rec.NumPoints3D() / 2);
  std::map<image_t, int> taken;
  size_t shortest_taken = 1000;
  for (point3D_t id : subset) {
    const Point3D& point = rec.GetPoint3D(id);
    shortest_taken = std::min(shortest_taken, point.track.Length());
    for (const TrackElement& el : point.track.elements) ++taken[el.image_id];
  }
  for (image_t id : rec.RegImageIds()) EXPECT_GE(taken[id], per_frame) << "frame " << id;
  // Longest first: a frame's points left out are no longer than the shortest it took, or
  // the frame had enough already.
  size_t longer_left_out = 0;
  for (const auto& [id, point] : rec.Points3D()) {
    longer_left_out += subset.count(id) == 0 && point.track.Length() > shortest_taken + 2;
  }
  EXPECT_LT(longer_left_out, rec.NumPoints3D() / 2);
}

TEST(MapperState, SubsetBundleDropsObservationsThatNoLongerFitTheMovedCameras) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, 0.0);
  Reconstruction& rec = state.reconstruction();
  const int per_frame = 40;
  const std::unordered_set<point3D_t> subset = state.LongestTrackPoints(per_frame);
  // One observation of each of a few points outside the subset moved 40 px: the subset
  // bundle re-triangulates those points from the cameras, and these observations do not fit.
  std::vector<TrackElement> moved;
  std::vector<point3D_t> ids;
  for (const auto& [id, point] : rec.Points3D()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  for (const point3D_t id : ids) {
    const Point3D& point = rec.GetPoint3D(id);
    if (subset.count(id) > 0 || point.track.Length() < 5) continue;
    moved.push_back(point.track.elements[1]);
    if (moved.size() == 10) break;
  }
  ASSERT_EQ(moved.size(), 10u);
  for (const TrackElement& el : moved) {
    rec.GetImage(el.image_id).points2D[el.point2D_idx].xy += Eigen::Vector2d(40.0, 0.0);
  }
  MapperReport report;
  state.SubsetBundle(&report, per_frame);
  for (const TrackElement& el : moved) {
    EXPECT_FALSE(rec.GetImage(el.image_id).points2D[el.point2D_idx].HasPoint3D())
        << "frame " << el.image_id << " observation " << el.point2D_idx;
  }
}

TEST(MapperState, SubsetBundleEndsAtTheFunctionToleranceItIsGiven) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState loose(p.input, options), tight(p.input, options);
  RegisterThenDisturb(p, loose);
  RegisterThenDisturb(p, tight);
  MapperReport loose_report, tight_report;
  loose.SubsetBundle(&loose_report, 40, {}, {}, 1e-2);
  tight.SubsetBundle(&tight_report, 40, {}, {}, 1e-10);
  ASSERT_EQ(loose_report.num_global_ba, 1);
  ASSERT_EQ(tight_report.num_global_ba, 1);
  EXPECT_LT(loose_report.num_global_ba_iterations, tight_report.num_global_ba_iterations);
}

TEST(MapperState, RefinementAfterACorrectionEndsWhereTheFullBundleDoes) {
  const MapperProblem p = WalkOutAndBack();
  IncrementalMapperOptions options = LoopOptions();
  options.loop_closure.refine_points_per_frame = 40;
  MapperState full(p.input, options), subset(p.input, options);
  RegisterThenDisturb(p, full);
  RegisterThenDisturb(p, subset);
  const testing::PoseError disturbed = testing::ComparePoses(full.reconstruction(), p);
  MapperReport full_report, subset_report;
  full.GlobalRefinement(&full_report);
  subset.RefineAfterCorrection(&subset_report, options.loop_closure.refine_function_tolerance);
  EXPECT_EQ(subset_report.num_global_ba, full_report.num_global_ba + 1);
  const testing::PoseError after_full = testing::ComparePoses(full.reconstruction(), p);
  const testing::PoseError after_subset = testing::ComparePoses(subset.reconstruction(), p);
  EXPECT_LT(after_full.max_centre_error, 0.1 * disturbed.max_centre_error);
  EXPECT_LT(after_subset.max_centre_error, 0.1 * disturbed.max_centre_error);
  // As close to the truth as the full bundle's answer (the same up to the solvers' ends).
  EXPECT_NEAR(after_subset.max_centre_error, after_full.max_centre_error,
              0.05 * after_full.max_centre_error);
  EXPECT_NEAR(after_subset.max_rotation_deg, after_full.max_rotation_deg,
              0.05 * after_full.max_rotation_deg + 1e-3);
}

TEST(LoopCloser, OptionsAreChecked) {
  LoopClosureOptions options;
  options.min_frame_gap = 1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.max_correction_scale = 0.9;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.split_refine_ties_per_group = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  for (const double tolerance : {0.0, 1.0}) {
    options = {};
    options.refine_function_tolerance = tolerance;
    EXPECT_THROW(options.Check(), InvalidArgument) << tolerance;
  }
  options = {};
  EXPECT_NO_THROW(options.Check());
}

}  // namespace
}  // namespace loopsfm
