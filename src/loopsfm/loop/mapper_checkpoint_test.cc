#include "loopsfm/sfm/mapper_checkpoint.h"

#include <gtest/gtest.h>

#include "loopsfm/loop/loop_closing.h"
#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {

using testing::MakeMapperProblem;
using testing::MapperProblem;
using testing::MapperProblemOptions;

// Two walks with no pair across the cut between them: two models, the second grown while
// the first is kept.
MapperProblem CutWalk() {
  MapperProblemOptions options;
  options.num_frames = 40;
  MapperProblem p = MakeMapperProblem(options);
  std::erase_if(p.input.pairs, [&](const MapperPair& pair) {
    const int a = static_cast<int>(pair.pair.image_id1) - 1;
    const int b = static_cast<int>(pair.pair.image_id2) - 1;
    return (a < 20) != (b < 20);
  });
  testing::RebuildTracks(&p.input);
  return p;
}

// A walk out and back along itself: loop evidence for the loop closer, split tracks.
MapperProblem WalkBack() {
  MapperProblemOptions options;
  options.num_frames = 60;
  options.walk_back = true;
  return MakeMapperProblem(options);
}

struct MapperRun {
  std::vector<Reconstruction> models;
  MapperReport report;
};

MapperRun Map(const MapperProblem& p, const IncrementalMapperOptions& options,
        const MapperCheckpointing& checkpointing = {}) {
  MapperRun run;
  run.models = MapWithLoopClosing(p.input, options, &run.report, {}, checkpointing);
  return run;
}

// Bit for bit: the same frames at the same poses, the same points at the same places.
void ExpectIdentical(const MapperRun& expected, const MapperRun& actual, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_EQ(expected.models.size(), actual.models.size());
  for (size_t m = 0; m < expected.models.size(); ++m) {
    const Reconstruction& a = expected.models[m];
    const Reconstruction& b = actual.models[m];
    ASSERT_EQ(a.RegImageIds(), b.RegImageIds()) << "model " << m;
    for (const image_t id : a.RegImageIds()) {
      EXPECT_EQ(a.GetImage(id).cam_from_world.rotation.coeffs(),
                b.GetImage(id).cam_from_world.rotation.coeffs()) << "frame " << id;
      EXPECT_EQ(a.GetImage(id).cam_from_world.translation,
                b.GetImage(id).cam_from_world.translation) << "frame " << id;
    }
    ASSERT_EQ(a.Point3DIds(), b.Point3DIds()) << "model " << m;
    for (const point3D_t id : a.Point3DIds()) {
      ASSERT_EQ(a.GetPoint3D(id).xyz, b.GetPoint3D(id).xyz) << "point " << id;
      ASSERT_EQ(a.GetPoint3D(id).track.elements, b.GetPoint3D(id).track.elements);
    }
    for (const auto& [id, camera] : a.Cameras()) EXPECT_EQ(camera.params, b.GetCamera(id).params);
  }
  EXPECT_EQ(expected.report.num_registered, actual.report.num_registered);
  EXPECT_EQ(expected.report.num_registered_on_retry, actual.report.num_registered_on_retry);
  EXPECT_EQ(expected.report.num_models_merged, actual.report.num_models_merged);
  EXPECT_EQ(expected.report.num_local_ba, actual.report.num_local_ba);
  EXPECT_EQ(expected.report.num_global_ba, actual.report.num_global_ba);
  EXPECT_EQ(expected.report.num_split_pairs, actual.report.num_split_pairs);
}

class MapperCheckpointTest : public ::testing::TestWithParam<int> {};

// Checkpoints are taken before every registration and once at the end; mapping resumed
// from any of them ends exactly where the uninterrupted run ended.
TEST_P(MapperCheckpointTest, ResumingFromAnyCheckpointGivesTheUninterruptedResult) {
  const bool walk_back = GetParam() == 1;
  const MapperProblem p = walk_back ? WalkBack() : CutWalk();
  IncrementalMapperOptions options;
  options.num_threads = 1;
  if (walk_back) {
    options.loop_closure.method = LoopClosingMethod::kBoth;
    // Windowed growth bundles from 20 frames on: the recent frames are part of the state.
    options.global_ba_window = 20;
  }

  std::vector<MapperCheckpoint> checkpoints;
  MapperCheckpointing saving;
  saving.interval_seconds = 0.0;
  saving.save = [&](const MapperCheckpoint& c) { checkpoints.push_back(c); };
  const MapperRun uninterrupted = Map(p, options, saving);
  ASSERT_EQ(uninterrupted.models.size(), walk_back ? 1u : 2u);
  // One before each registration, and the finished state.
  ASSERT_GE(checkpoints.size(), static_cast<size_t>(uninterrupted.report.num_registered));
  EXPECT_TRUE(checkpoints.back().finished);
  EXPECT_EQ(std::count_if(checkpoints.begin(), checkpoints.end(),
                          [](const MapperCheckpoint& c) { return c.finished; }), 1);
  // The cut walk is mapped as two models first: states with a kept model and a growing one.
  const auto two_models = std::find_if(checkpoints.begin(), checkpoints.end(),
                                       [](const MapperCheckpoint& c) {
                                         return !c.kept.empty() && c.growing.has_value();
                                       });
  EXPECT_EQ(two_models != checkpoints.end(), !walk_back);

  const size_t n = checkpoints.size();
  std::vector<size_t> resume_from = {n / 3, 2 * n / 3, n - 1};
  if (two_models != checkpoints.end()) resume_from[0] = two_models - checkpoints.begin();
  for (const size_t k : resume_from) {
    MapperCheckpointing resuming;
    resuming.resume = &checkpoints[k];
    ExpectIdentical(uninterrupted, Map(p, options, resuming),
                    "resumed from checkpoint " + std::to_string(k) + " of " + std::to_string(n) +
                        " (" + std::to_string(checkpoints[k].NumRegistered()) + " registered)");
  }
}

INSTANTIATE_TEST_SUITE_P(Problems, MapperCheckpointTest, ::testing::Values(0, 1),
                         [](const auto& info) { return info.param ? "WalkBack" : "CutWalk"; });

// A checkpoint that does not fit the input (another video's frames) is set aside: mapping
// starts from the beginning and gives what it gives without one.
TEST(MapperCheckpoint, ACheckpointOfOtherFramesIsSetAside) {
  const MapperProblem p = CutWalk();
  IncrementalMapperOptions options;
  options.num_threads = 1;
  std::vector<MapperCheckpoint> checkpoints;
  MapperCheckpointing saving;
  saving.interval_seconds = 0.0;
  saving.save = [&](const MapperCheckpoint& c) { checkpoints.push_back(c); };
  const MapperRun uninterrupted = Map(p, options, saving);
  ASSERT_GT(checkpoints.size(), 10u);

  MapperCheckpoint foreign = checkpoints[checkpoints.size() / 2];
  ASSERT_TRUE(foreign.growing.has_value());
  foreign.growing->state.registered.push_back({9999, Rigid3d()});
  MapperCheckpointing resuming;
  resuming.resume = &foreign;
  ExpectIdentical(uninterrupted, Map(p, options, resuming), "frame 9999 is not an input frame");

  MapperCheckpoint not_finite = checkpoints[checkpoints.size() / 2];
  not_finite.growing->state.registered.back().cam_from_world.translation.x() = std::nan("");
  resuming.resume = &not_finite;
  ExpectIdentical(uninterrupted, Map(p, options, resuming), "a pose is not finite");

  MapperCheckpoint broken = checkpoints[checkpoints.size() / 2];
  broken.random_state = "not a state";
  resuming.resume = &broken;
  ExpectIdentical(uninterrupted, Map(p, options, resuming), "random state garbled");
}

}  // namespace
}  // namespace loopsfm
