#include "loopsfm/pipeline/segment_mapping.h"

#include <gtest/gtest.h>

#include <numeric>

#include <unistd.h>

#include <filesystem>
#include <iostream>
#include <string>
#include <thread>

#include <tbb/global_control.h>

#include "loopsfm/loop/loop_closing.h"
#include "loopsfm/sfm/global_mapper.h"
#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/sfm/loop_test_problem.h"
#include "loopsfm/sfm/sfm_test_problem.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using Plan = std::vector<std::pair<size_t, size_t>>;

TEST(PlanSegments, CoversTheFramesWithEqualSegmentsThatOverlap) {
  // 100 frames, 4 segments sharing 10: 4 x 33 - 3 x 10 = 102 >= 100.
  EXPECT_EQ(PlanSegments(100, 4, 10), (Plan{{0, 33}, {23, 56}, {46, 79}, {69, 100}}));
  EXPECT_EQ(PlanSegments(100, 1, 10), (Plan{{0, 100}}));
  EXPECT_EQ(PlanSegments(0, 4, 10), Plan{});
  // Segments shorter than twice the overlap are not made: 40 frames give 3 of 20, not 4.
  EXPECT_EQ(PlanSegments(40, 4, 10), (Plan{{0, 20}, {10, 30}, {20, 40}}));
  EXPECT_EQ(PlanSegments(15, 4, 10), (Plan{{0, 15}}));
}

TEST(PlanSegments, ByCostCutsWhereTheSegmentsCostTheSame) {
  // Equal costs: the equal segments.
  for (const auto& [frames, count] : {std::pair{100, 4}, {100, 1}, {40, 4}, {15, 4}, {281, 4}}) {
    EXPECT_EQ(PlanSegmentsByCost(std::vector<double>(frames, 1.0), count, 10),
              PlanSegments(frames, count, 10))
        << frames << " frames, " << count << " segments";
  }
  EXPECT_EQ(PlanSegmentsByCost({}, 4, 10), Plan{});
  // The first 40 frames cost 3 each, the other 60 one each. Equal frames give segments that
  // cost 99, 67, 33 and 31; by cost each costs 63: (0, 21), (11, 32), (22, 49), (39, 100).
  // The segments still overlap by 10 frames and cover all.
  std::vector<double> costs(100, 1.0);
  std::fill(costs.begin(), costs.begin() + 40, 3.0);
  auto cost_of = [&](const std::pair<size_t, size_t>& segment) {
    return std::accumulate(costs.begin() + segment.first, costs.begin() + segment.second, 0.0);
  };
  auto most = [&](const Plan& plan) {
    double m = 0.0;
    for (const auto& segment : plan) m = std::max(m, cost_of(segment));
    return m;
  };
  const Plan equal = PlanSegments(100, 4, 10);
  const Plan by_cost = PlanSegmentsByCost(costs, 4, 10);
  EXPECT_EQ(most(equal), 99.0);
  EXPECT_EQ(by_cost, (Plan{{0, 21}, {11, 32}, {22, 49}, {39, 100}}));
  for (const auto& segment : by_cost) EXPECT_EQ(cost_of(segment), 63.0);
  EXPECT_EQ(by_cost.front().first, 0u);
  EXPECT_EQ(by_cost.back().second, 100u);
  for (size_t k = 0; k < by_cost.size(); ++k) {
    EXPECT_GE(by_cost[k].second - by_cost[k].first, 20u);
    if (k > 0) {
      EXPECT_EQ(by_cost[k - 1].second - by_cost[k].first, 10u);
    }
  }
  // Whatever the costs, a segment has at least twice the overlap: all the cost in the last
  // frame leaves the others together.
  std::vector<double> last(100, 0.0);
  last.back() = 1.0;
  for (const auto& segment : PlanSegmentsByCost(last, 4, 10)) {
    EXPECT_GE(segment.second - segment.first, 20u);
  }
}

TEST(SegmentMapping, OptionsAreChecked) {
  SegmentMappingOptions options;
  options.num_segments = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.overlap = 1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.num_parallel = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  EXPECT_NO_THROW(SegmentMappingOptions().Check());

  const testing::MapperProblem p = testing::MakeMapperProblem({});
  IncrementalMapperOptions mapper_options = testing::LoopOptions();
  mapper_options.loop_closure.withhold_loop_pairs = true;
  EXPECT_THROW(MapInSegments(p.input, mapper_options, {}, nullptr, nullptr), InvalidArgument);
}

// The walk out and back (80 frames, a loop) in three segments: merged into one model of
// every frame, as accurate as the whole walk mapped at once, the loop pairs between the
// first and the last segment used at the end.
TEST(SegmentMapping, ThreeSegmentsOfALoopWalkMergeIntoOneModel) {
  const testing::MapperProblem p = testing::WalkOutAndBack();
  const IncrementalMapperOptions mapper_options = testing::LoopOptions();
  SegmentMappingOptions options;
  options.num_segments = 3;
  options.overlap = 8;
  SegmentMappingReport report;
  MapperReport mapper_report;
  const std::vector<Reconstruction> models =
      MapInSegments(p.input, mapper_options, options, &report, &mapper_report);
  ASSERT_EQ(models.size(), 1u);
  ASSERT_EQ(report.segments.size(), 3u);
  EXPECT_FALSE(report.segments[0].merged);
  EXPECT_TRUE(report.segments[1].merged);
  EXPECT_TRUE(report.segments[2].merged);
  for (const SegmentReport& segment : report.segments) {
    EXPECT_EQ(segment.num_registered, segment.num_frames);
  }
  EXPECT_EQ(models[0].NumRegImages(), 80u);
  EXPECT_EQ(mapper_report.num_models, 1);
  EXPECT_EQ(mapper_report.num_registered, 80);
  const testing::PoseError error = testing::ComparePoses(models[0], p);

  const std::vector<Reconstruction> whole = MapWithLoopClosing(p.input, mapper_options, nullptr);
  ASSERT_FALSE(whole.empty());
  const testing::PoseError whole_error = testing::ComparePoses(whole[0], p);
  EXPECT_LT(error.max_centre_error, std::max(1.25 * whole_error.max_centre_error, 0.002));
  EXPECT_LT(error.max_rotation_deg, std::max(1.25 * whole_error.max_rotation_deg, 0.1));
}

// The global mapper on each of three segments of the loop walk: merged into one model of
// every frame, as accurate as the global mapper on the whole walk, with no checkpoints (the
// global mapper has none).
TEST(SegmentMapping, SegmentsMappedByTheGlobalMapperMergeIntoOneModel) {
  const testing::MapperProblem p = testing::WalkOutAndBack();
  SegmentMappingOptions options;
  options.num_segments = 3;
  options.overlap = 8;
  options.global_mapper = GlobalMapperOptions();
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("loopsfm_global_segments_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  options.checkpoint_dir = dir;
  SegmentMappingReport report;
  const std::vector<Reconstruction> models =
      MapInSegments(p.input, testing::LoopOptions(), options, &report, nullptr);
  EXPECT_TRUE(report.global);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_EQ(models[0].NumRegImages(), 80u);
  const double error = testing::ComparePoses(models[0], p).max_centre_error;
  // Against the global mapper on the whole walk.
  const std::vector<Reconstruction> whole =
      RunGlobalMapper(p.input, testing::LoopOptions(), GlobalMapperOptions(), nullptr, nullptr);
  ASSERT_FALSE(whole.empty());
  const double whole_error = testing::ComparePoses(whole[0], p).max_centre_error;
  std::cout << "[ info     ] max centre error: global segments " << error << ", global whole "
            << whole_error << "\n";
  EXPECT_LT(error, std::max(1.25 * whole_error, 0.002));
  EXPECT_FALSE(std::filesystem::exists(dir));
}

// Segments whose global models are doubtful (a third of the keypoints 50 px off: positioning
// leaves many observations off, as the wrong matches of repeated structure do) are set aside
// and mapped again by the incremental mapper, unless remap_doubtful_global is off.
TEST(SegmentMapping, DoubtfulGlobalSegmentsAreMappedAgainIncrementally) {
  testing::MapperProblemOptions problem;
  problem.num_frames = 40;
  testing::MapperProblem p = testing::MakeMapperProblem(problem);
  for (MapperFrame& frame : p.input.frames) {
    for (size_t k = 0; k < frame.points2D.size(); k += 3) {
      frame.points2D[k] += Eigen::Vector2d(40.0, 30.0);
    }
  }
  SegmentMappingOptions options;
  options.num_segments = 2;
  options.overlap = 8;
  options.global_mapper = GlobalMapperOptions();
  for (const bool remap : {true, false}) {
    options.remap_doubtful_global = remap;
    SegmentMappingReport report;
    MapperReport mapper_report;
    const std::vector<Reconstruction> models =
        MapInSegments(p.input, testing::LoopOptions(), options, &report, &mapper_report);
    ASSERT_EQ(report.segments.size(), 2u);
    for (const SegmentReport& segment : report.segments) {
      EXPECT_EQ(segment.global_set_aside, remap) << "remap " << remap;
      EXPECT_GT(segment.num_registered, segment.num_frames / 2) << "remap " << remap;
    }
    EXPECT_FALSE(models.empty());
  }
}

// The same models whether the segments are mapped one at a time, all at once, or on other
// ranks (each segment's mapping depends only on its frames and the options; a model comes
// back from another rank bit for bit).
TEST(SegmentMapping, SegmentsMappedAtOnceOrOnOtherRanksGiveTheSameModel) {
  testing::MapperProblemOptions problem;
  problem.num_frames = 40;
  const testing::MapperProblem p = testing::MakeMapperProblem(problem);
  SegmentMappingOptions options;
  options.num_segments = 3;
  options.overlap = 6;
  options.num_parallel = 1;
  const std::vector<Reconstruction> one_at_a_time =
      MapInSegments(p.input, testing::LoopOptions(), options, nullptr, nullptr);
  options.num_parallel = 3;
  const std::vector<Reconstruction> at_once =
      MapInSegments(p.input, testing::LoopOptions(), options, nullptr, nullptr);

  // Three ranks (threads here, as tests/e2e runs them under mpirun): one segment each.
  tbb::global_control pool(tbb::global_control::max_allowed_parallelism, 8);
  auto ranks = InProcessRanks(3);
  std::vector<std::thread> workers;
  for (int r = 1; r < 3; ++r) workers.emplace_back([&ranks, r] { ServeStageWork(*ranks[r], 1); });
  std::vector<Reconstruction> on_ranks;
  std::vector<size_t> segments_per_rank;
  {
    WorkSharing sharing(ranks[0].get(), 1);
    options.sharing = &sharing;
    on_ranks = MapInSegments(p.input, testing::LoopOptions(), options, nullptr, nullptr);
    segments_per_rank = sharing.UnitsPerRank();
  }
  for (std::thread& worker : workers) worker.join();
  EXPECT_EQ(segments_per_rank, (std::vector<size_t>{1, 1, 1}));

  ASSERT_EQ(one_at_a_time.size(), 1u);
  EXPECT_EQ(one_at_a_time[0].NumRegImages(), 40u);
  for (const std::vector<Reconstruction>* other : {&at_once, static_cast<const std::vector<Reconstruction>*>(&on_ranks)}) {
    ASSERT_EQ(other->size(), 1u);
    const Reconstruction& model = (*other)[0];
    EXPECT_EQ(model.NumPoints3D(), one_at_a_time[0].NumPoints3D());
    for (const image_t id : one_at_a_time[0].RegImageIds()) {
      ASSERT_TRUE(model.IsRegistered(id));
      EXPECT_EQ(model.GetImage(id).cam_from_world.translation,
                one_at_a_time[0].GetImage(id).cam_from_world.translation);
    }
  }
}

// A segment that breaks into two models: the second segment (frames 17-39) has no pair
// across frame 24 within it, so it maps 24-39 and leaves 17-23 out; the first segment's
// frames 17-22 and the pairs of frames before 17 with 24 and after tie the two segments
// together. Frame 23, in no merged model, is registered after the merge: every frame ends
// in one model.
TEST(SegmentMapping, FramesASegmentLeftOutAreRegisteredAfterTheMerge) {
  testing::MapperProblemOptions problem;
  problem.num_frames = 40;
  testing::MapperProblem p = testing::MakeMapperProblem(problem);
  std::erase_if(p.input.pairs, [&](const MapperPair& pair) {
    const image_t a = std::min(pair.pair.image_id1, pair.pair.image_id2);
    const image_t b = std::max(pair.pair.image_id1, pair.pair.image_id2);
    return a >= 18 && a <= 24 && b >= 25;  // image ids are frame indices + 1
  });
  testing::RebuildTracks(&p.input);
  SegmentMappingOptions options;
  options.num_segments = 2;
  options.overlap = 6;
  SegmentMappingReport report;
  const std::vector<Reconstruction> models =
      MapInSegments(p.input, testing::LoopOptions(), options, &report, nullptr);
  ASSERT_EQ(report.segments.size(), 2u);
  EXPECT_LT(report.segments[1].num_registered, report.segments[1].num_frames);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_EQ(models[0].NumRegImages(), 40u);
  EXPECT_LT(testing::ComparePoses(models[0], p).max_centre_error, 0.005);
}


// Segments that share no frame and no pair do not merge: two models.
TEST(SegmentMapping, SegmentsThatShareNothingStayApart) {
  testing::MapperProblemOptions problem;
  problem.num_frames = 40;
  testing::MapperProblem p = testing::MakeMapperProblem(problem);
  // Two walks: no pair across frame 20 (the segments' overlap has only pairs to one side).
  std::erase_if(p.input.pairs, [&](const MapperPair& pair) {
    return (pair.pair.image_id1 <= 20) != (pair.pair.image_id2 <= 20);
  });
  testing::RebuildTracks(&p.input);
  SegmentMappingOptions options;
  options.num_segments = 2;
  options.overlap = 4;
  SegmentMappingReport report;
  const std::vector<Reconstruction> models =
      MapInSegments(p.input, testing::LoopOptions(), options, &report, nullptr);
  ASSERT_EQ(report.segments.size(), 2u);
  EXPECT_FALSE(report.segments[1].merged);
  EXPECT_EQ(models.size(), 2u);
}

}  // namespace
}  // namespace loopsfm
