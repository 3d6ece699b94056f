#include "loopsfm/sfm/incremental_mapper.h"

#include <gtest/gtest.h>

#include <functional>
#include <map>

#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {

using testing::ComparePoses;
using testing::MakeMapperProblem;
using testing::MapperProblem;
using testing::MapperProblemOptions;

// Maps the problem's walk and expects every frame in one model, near its true pose.
void ExpectOneAccurateModel(const MapperProblem& p, const IncrementalMapperOptions& options,
                            MapperReport* report) {
  const auto models = RunIncrementalMapper(p.input, options, report);
  ASSERT_EQ(models.size(), 1u);
  const auto error = ComparePoses(models[0], p);
  EXPECT_EQ(error.num_registered, static_cast<int>(p.input.frames.size()));
  EXPECT_LT(error.max_centre_error, 2e-3);
  EXPECT_LT(error.max_rotation_deg, 0.2);
}

// Maps the walk once for each value of an option (`set` puts it in), expecting one accurate
// model and no failed bundle each time; returns each run's number of global bundles.
template <typename T>
std::map<T, int> GlobalBundlesPerValue(
    const MapperProblem& p, std::initializer_list<T> values,
    const std::function<void(IncrementalMapperOptions&, T)>& set) {
  std::map<T, int> num_global_ba;
  for (const T value : values) {
    SCOPED_TRACE(value);
    IncrementalMapperOptions options;
    options.num_threads = 1;
    set(options, value);
    MapperReport report;
    ExpectOneAccurateModel(p, options, &report);
    EXPECT_EQ(report.num_failed_bundles, 0);
    num_global_ba[value] = report.num_global_ba;
  }
  return num_global_ba;
}

TEST(IncrementalMapper, RegistersAWalkInOneAccurateModel) {
  const MapperProblem p = MakeMapperProblem({});
  ASSERT_EQ(p.input.frames.size(), 30u);
  IncrementalMapperOptions options;
  options.num_threads = 1;
  MapperReport report;
  ASSERT_NO_FATAL_FAILURE(ExpectOneAccurateModel(p, options, &report));
  EXPECT_EQ(report.num_failed_bundles, 0);
  EXPECT_EQ(report.num_init_accepted, 1);
}

// The last frame also holds 1500 clutter keypoints wrongly linked (by panoramic pairs,
// which no initial pair can use) to points only the first three frames see. The model
// starts at the beginning of the walk (the wall is richer there), where the last frame
// seems to see many of its points, but too few of them fit for a pose. It must not be
// given up: once the model reaches it, it registers at its true pose.
TEST(IncrementalMapper, RetriesAFrameThatFailedOnceTheModelSeesMoreOfIt) {
  MapperProblemOptions problem_options;
  problem_options.extra_points_at_start = 1500;
  MapperProblem p = MakeMapperProblem(problem_options);
  Random random(5);
  const int target = problem_options.num_frames - 1;
  MapperFrame& frame = p.input.frames[target];
  std::vector<bool> used(p.points.size(), false);
  for (int point : p.keypoint_point[target]) used[point] = true;
  const size_t num_real = frame.points2D.size();
  for (int source = 0; source < 3; ++source) {
    MapperPair clutter;
    clutter.pair = ImagePair(p.input.frames[source].image_id, frame.image_id);
    clutter.geometry.config = TwoViewGeometry::kPanoramic;
    for (size_t k = 0; k < p.keypoint_point[source].size(); ++k) {
      const int point = p.keypoint_point[source][k];
      if (used[point] || clutter.geometry.inlier_matches.size() >= 500) continue;
      used[point] = true;
      clutter.geometry.inlier_matches.push_back(
          {static_cast<point2D_t>(k), static_cast<point2D_t>(frame.points2D.size())});
      frame.points2D.emplace_back(random.UniformReal(0, 640), random.UniformReal(0, 480));
      p.keypoint_point[target].push_back(-1);
    }
    p.input.pairs.push_back(clutter);
  }
  ASSERT_EQ(frame.points2D.size(), num_real + 1500);
  testing::RebuildTracks(&p.input);

  IncrementalMapperOptions options;
  options.num_threads = 1;
  // Frames next in time to the model go first by default, which would reach the last frame
  // from its neighbours without an early try; ranked by visible tracks alone it is tried
  // early and fails.
  options.registration_capture_window = 0;
  MapperReport report;
  const auto models = RunIncrementalMapper(p.input, options, &report);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_TRUE(models[0].IsRegistered(frame.image_id));
  EXPECT_GE(report.num_registered_on_retry, 1);
  const auto error = ComparePoses(models[0], p);
  EXPECT_EQ(error.num_registered, 30);
  EXPECT_LT(error.max_centre_error, 2e-3);
}

// Two walks that share no verified pair at first: the mapper builds two models. A few
// pairs between their ends link them; the models must come out merged into one.
TEST(IncrementalMapper, MergesModelsLinkedByVerifiedPairs) {
  MapperProblemOptions problem_options;
  problem_options.num_frames = 40;
  MapperProblem p = MakeMapperProblem(problem_options);
  // Cut the video between frames 19 and 20 except for pairs (18, 21) and (19, 22) ...
  std::erase_if(p.input.pairs, [&](const MapperPair& pair) {
    const int a = static_cast<int>(pair.pair.image_id1) - 1, b = static_cast<int>(pair.pair.image_id2) - 1;
    return (a < 20) != (b < 20);
  });
  testing::RebuildTracks(&p.input);
  IncrementalMapperOptions options;
  options.num_threads = 1;
  {
    MapperReport report;
    const auto models = RunIncrementalMapper(p.input, options, &report);
    EXPECT_EQ(models.size(), 2u) << "the cut must separate the walk";
  }
  // ... now link them with two pairs across the cut: too few tracks for either model to
  // register the other's frames, enough common points for a similarity.
  p.input.pairs.push_back(testing::MakeTruePair(p, 17, 22));
  p.input.pairs.push_back(testing::MakeTruePair(p, 18, 23));
  testing::RebuildTracks(&p.input);
  MapperReport report;
  const auto models = RunIncrementalMapper(p.input, options, &report);
  ASSERT_EQ(models.size(), 1u);
  const auto error = ComparePoses(models[0], p);
  EXPECT_EQ(error.num_registered, 40);
  EXPECT_LT(error.max_centre_error, 2e-3);
}

// Growth ends with a global bundle (when no frame registers), so one that growth calls for
// within the last global_ba_end_margin of the frames is skipped: the model is refined as
// well, with one full bundle fewer. On this 29-frame walk (initial pair of 2, growth 0.5)
// the last growth bundle falls at 27 frames, two before the end (measured: 8 global bundles
// without the margin, 7 with it, largest centre error 7.1e-4 both).
TEST(IncrementalMapper, SkipsAGrowthBundleThatTheEndingBundleFollowsClosely) {
  MapperProblemOptions problem_options;
  problem_options.num_frames = 29;
  const MapperProblem p = MakeMapperProblem(problem_options);
  ASSERT_EQ(p.input.frames.size(), 29u);
  const std::map<double, int> num_global_ba = GlobalBundlesPerValue<double>(
      p, {0.0, 0.1}, [](IncrementalMapperOptions& o, double margin) { o.global_ba_end_margin = margin; });
  EXPECT_EQ(num_global_ba.at(0.1), num_global_ba.at(0.0) - 1);
}

// Growth bundles of a model larger than global_ba_window move only its most recent frames:
// a 60-frame walk with a 20-frame window is mapped as accurately as with whole-model
// bundles. Growth refinements at 3, 5, 8, 12 and 18 frames either way; then at 27 and 41
// without the window, and with it windowed ones every 10 frames (half the window, fewer than
// the growth fraction): 27, 37 and 47 (57 is skipped, the end being near).
TEST(IncrementalMapper, WindowedGrowthBundlesMapAsAccurately) {
  MapperProblemOptions problem_options;
  problem_options.num_frames = 60;
  const MapperProblem p = MakeMapperProblem(problem_options);
  const std::map<int, int> num_global_ba = GlobalBundlesPerValue<int>(
      p, {0, 20}, [](IncrementalMapperOptions& o, int window) { o.global_ba_window = window; });
  EXPECT_EQ(num_global_ba.at(20), num_global_ba.at(0) + 1);
}

}  // namespace
}  // namespace loopsfm
