#include "loopsfm/loop/loop_closure.h"

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

using testing::LoopOptions;
using testing::MapperProblem;
using testing::RegisterTurnedAndScaled;
using testing::RegisterWithDrift;
using testing::WalkOutAndBack;

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
