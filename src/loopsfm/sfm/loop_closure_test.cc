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
