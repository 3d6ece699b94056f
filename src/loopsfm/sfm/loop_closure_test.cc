#include "loopsfm/sfm/loop_closure.h"

#include <gtest/gtest.h>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/loop_test_problem.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using testing::MapperProblem;
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

TEST(LoopCloser, DriftedWalkBackIsClosedAndItsEndsFused) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state(p.input, options);
  // 1.5 cm a frame: 0.6 m at the end of the walk back, 30-40 px against the first frames.
  RegisterWithDrift(p, state, 0.015);
  const testing::PoseError before = testing::ComparePoses(state.reconstruction(), p);
  const size_t points_before = state.reconstruction().NumPoints3D();

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

TEST(LoopCloser, OptionsAreChecked) {
  LoopClosureOptions options;
  options.min_frame_gap = 1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.max_correction_scale = 0.9;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
