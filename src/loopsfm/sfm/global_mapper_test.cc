#include "loopsfm/sfm/global_mapper.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "loopsfm/scene/random_rotations.h"
#include "loopsfm/sfm/global_structure.h"
#include "loopsfm/sfm/sfm_test_problem.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using testing::MakeMapperProblem;
using testing::MapperProblem;
using testing::MapperProblemOptions;

IncrementalMapperOptions OneThread() {
  IncrementalMapperOptions options;
  options.num_threads = 1;
  return options;
}

// A walk out and back along a wall (a loop: the walk back sees what the walk out saw), its
// pairs' rotations measured with `noise_deg` of noise, and every `outlier_every`-th pair's
// rotation replaced by one far from the truth (0: none).
MapperProblem NoisyWalkBack(double noise_deg, int outlier_every) {
  MapperProblemOptions options;
  options.num_frames = 50;
  options.walk_back = true;
  MapperProblem p = MakeMapperProblem(options);
  Random random(11);
  for (size_t k = 0; k < p.input.pairs.size(); ++k) {
    Eigen::Quaterniond& rotation = p.input.pairs[k].geometry.cam2_from_cam1.rotation;
    rotation = outlier_every > 0 && k % outlier_every == 0
                   ? testing::OutlierRotation(rotation, random)
                   : (testing::Noise(random, noise_deg) * rotation).normalized();
  }
  return p;
}

// Every frame of NoisyWalkBack registered, within 2 cm and 0.2 deg of the truth.
void ExpectWalkBackMapped(const Reconstruction& model, const MapperProblem& p) {
  const testing::PoseError error = testing::ComparePoses(model, p);
  EXPECT_EQ(error.num_registered, 50);
  // ComparePoses gives the error as a fraction of the distance between the first and the
  // last frame, which the walk back brings close together: in metres, against a walk of
  // 2 x 7.5 m.
  const double ends = (p.cam_from_world.front().Inverse().translation -
                       p.cam_from_world.back().Inverse().translation).norm();
  EXPECT_LT(error.max_centre_error * ends, 0.02);
  EXPECT_LT(error.max_rotation_deg, 0.2);
}

TEST(GlobalMapper, LoopWalkIsMappedWholeDespiteOutlierPairs) {
  const MapperProblem p = NoisyWalkBack(0.3, 15);
  GlobalMapperReport report;
  MapperReport mapper_report;
  const std::vector<Reconstruction> models =
      RunGlobalMapper(p.input, OneThread(), GlobalMapperOptions(), &report, &mapper_report);
  ASSERT_EQ(models.size(), 1u);
  ExpectWalkBackMapped(models[0], p);
  // Every planted outlier pair is dropped around triangles or left disagreeing with the
  // averaged rotations.
  const int outliers = static_cast<int>((p.input.pairs.size() + 14) / 15);
  EXPECT_EQ(report.num_view_graph_edges, static_cast<int>(p.input.pairs.size()));
  EXPECT_EQ(report.num_cuts, 0);  // every frame has a pair with the next, where it turns too
  EXPECT_EQ(report.num_pairs_across_cuts, 0);
  EXPECT_GE(report.view_graph.num_dropped_by_triangles + report.num_rotation_outliers, outliers);
  EXPECT_EQ(report.num_registered, 50);
  EXPECT_GT(report.positioning.num_observations, 0);
  EXPECT_GE(mapper_report.num_global_ba, 2);
}

// The walk back sees the points of the walk out again, so its tracks are long; global
// positioning takes at most max_observations_per_track of each, and still maps the walk.
TEST(GlobalMapper, PositioningTakesAtMostTheCapOfEachTrack) {
  const MapperProblem p = NoisyWalkBack(0.3, 0);
  GlobalMapperOptions uncapped;
  uncapped.max_observations_per_track = 1000;
  GlobalMapperReport report;
  RunGlobalMapper(p.input, OneThread(), uncapped, &report, nullptr);
  ASSERT_GT(report.num_tracks_positioned, 0);
  EXPECT_GT(report.positioning.num_observations, 4 * report.num_tracks_positioned);

  GlobalMapperOptions capped;
  capped.max_observations_per_track = 4;
  const std::vector<Reconstruction> models =
      RunGlobalMapper(p.input, OneThread(), capped, &report, nullptr);
  ASSERT_GT(report.num_tracks_positioned, 0);
  EXPECT_LE(report.positioning.num_observations, 4 * report.num_tracks_positioned);
  ASSERT_EQ(models.size(), 1u);
  ExpectWalkBackMapped(models[0], p);
}

// A walk whose view graph falls apart at frame 25 (no pair across it): parts of 25 and 15
// frames.
MapperProblem WalkInTwoParts() {
  MapperProblemOptions options;
  options.num_frames = 40;
  MapperProblem p = MakeMapperProblem(options);
  std::erase_if(p.input.pairs, [&](const MapperPair& pair) {
    return (pair.pair.image_id1 <= 25) != (pair.pair.image_id2 <= 25);
  });
  testing::RebuildTracks(&p.input);
  return p;
}

TEST(GlobalMapper, EachPartOfAViewGraphThatFallsApartIsAModel) {
  const MapperProblem p = WalkInTwoParts();
  GlobalMapperReport report;
  MapperReport mapper_report;
  const std::vector<Reconstruction> models =
      RunGlobalMapper(p.input, OneThread(), GlobalMapperOptions(), &report, &mapper_report);
  ASSERT_EQ(models.size(), 2u);
  EXPECT_EQ(models[0].NumRegImages(), 25u);
  EXPECT_EQ(models[1].NumRegImages(), 15u);
  EXPECT_TRUE(models[0].IsRegistered(1) && models[1].IsRegistered(26));
  EXPECT_EQ(report.num_components, 2);
  EXPECT_EQ(report.num_components_mapped, 2);
  // A cut with no pair across: nothing to join the parts by.
  EXPECT_EQ(report.num_cuts, 1);
  EXPECT_EQ(report.num_pairs_across_cuts, 0);
  EXPECT_EQ(report.num_registered, 40);
  EXPECT_EQ(mapper_report.num_models, 2);
  EXPECT_EQ(mapper_report.num_registered, 40);
  for (const Reconstruction& model : models) {
    const testing::PoseError error = testing::ComparePoses(model, p);
    EXPECT_LT(error.max_centre_error, 0.005);
    EXPECT_LT(error.max_rotation_deg, 0.1);
  }
}

TEST(GlobalMapper, PartsSmallerThanAModelOrBeyondTheLimitAreLeftOut) {
  const MapperProblem p = WalkInTwoParts();
  IncrementalMapperOptions mapper_options = OneThread();
  mapper_options.min_model_size = 16;
  GlobalMapperReport report;
  std::vector<Reconstruction> models =
      RunGlobalMapper(p.input, mapper_options, GlobalMapperOptions(), &report, nullptr);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_EQ(models[0].NumRegImages(), 25u);
  EXPECT_EQ(report.num_frames_in_other_components, 15);

  mapper_options = OneThread();
  mapper_options.max_num_models = 1;
  models = RunGlobalMapper(p.input, mapper_options, GlobalMapperOptions(), &report, nullptr);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_EQ(models[0].NumRegImages(), 25u);

  GlobalMapperOptions largest_only;
  largest_only.view_graph.keep_largest_component = true;
  models = RunGlobalMapper(p.input, OneThread(), largest_only, &report, nullptr);
  ASSERT_EQ(models.size(), 1u);
  EXPECT_EQ(models[0].NumRegImages(), 25u);
  EXPECT_GT(report.view_graph.num_dropped_outside_component, 0);
}

// A walk of 45 frames that the video cuts between frames 21 and 22 (indices; image ids are
// one more): of the pairs across the cut, only the 12 long ones from frames 19-21 to frames
// 24-27 are left, and each one's rotation is 25 deg off, about a direction of its own (each
// pair's two-view geometry is wrong in its own way). Their inliers stay, so tracks still
// cross the cut.
constexpr int kCutFrame = 22;
constexpr int kPairsAcrossCut = 12;

MapperProblem WalkWithACut() {
  MapperProblemOptions options;
  options.num_frames = 45;
  MapperProblem p = MakeMapperProblem(options);
  auto first_frame = [](const MapperPair& pair) {
    return static_cast<int>(std::min(pair.pair.image_id1, pair.pair.image_id2)) - 1;
  };
  auto last_frame = [](const MapperPair& pair) {
    return static_cast<int>(std::max(pair.pair.image_id1, pair.pair.image_id2)) - 1;
  };
  std::erase_if(p.input.pairs, [&](const MapperPair& pair) {
    const int from = first_frame(pair), to = last_frame(pair);
    const bool across = from < kCutFrame && to >= kCutFrame;
    const bool long_one = from >= kCutFrame - 3 && to >= kCutFrame + 2 && to <= kCutFrame + 5;
    return across && !long_one;
  });
  int across = 0;
  for (MapperPair& pair : p.input.pairs) {
    if (first_frame(pair) >= kCutFrame || last_frame(pair) < kCutFrame) continue;
    // Axes 30 deg apart in the image plane: any two of these pairs disagree by more than
    // 12 deg around a triangle (the view graph's bound is 5 deg).
    const double axis_angle = 2.0 * M_PI * across++ / kPairsAcrossCut;
    const Eigen::Vector3d axis(std::cos(axis_angle), std::sin(axis_angle), 0.0);
    Eigen::Quaterniond& rotation = pair.geometry.cam2_from_cam1.rotation;
    rotation =
        (Eigen::Quaterniond(Eigen::AngleAxisd(25.0 * M_PI / 180.0, axis)) * rotation).normalized();
  }
  EXPECT_EQ(across, kPairsAcrossCut);
  testing::RebuildTracks(&p.input);
  return p;
}

// The pairs across the cut stay out of the view graph; the two parts are mapped apart and
// joined by the points they share into one model of the whole walk, within 2 cm and 0.2 deg
// of the truth (measured: 0.9 cm, 0.06 deg). Without split_at_cuts, the pairs across enter
// the view graph, where their rotations disagree around every triangle they are in, so
// cleaning drops them all and the walk falls apart into two models. (Had every pair across
// been off by one and the same turn, cleaning would keep them, and here the bundles would
// turn the far side back, even from a turn of 90 deg.)
TEST(GlobalMapper, PartsOfAVideoCutAreJoinedByTheirSharedPoints) {
  const MapperProblem p = WalkWithACut();
  GlobalMapperOptions options;
  ASSERT_TRUE(options.split_at_cuts);  // the default
  GlobalMapperReport report;
  MapperReport mapper_report;
  std::vector<Reconstruction> models =
      RunGlobalMapper(p.input, OneThread(), options, &report, &mapper_report);
  EXPECT_EQ(report.num_cuts, 1);
  EXPECT_EQ(report.num_pairs_across_cuts, kPairsAcrossCut);
  EXPECT_EQ(report.num_view_graph_edges, static_cast<int>(p.input.pairs.size()) - kPairsAcrossCut);
  EXPECT_EQ(report.num_components_mapped, 2);
  EXPECT_EQ(mapper_report.num_models_merged, 1);
  // One loose bundle per part, then the merge's refinement of the whole; nothing is left to
  // register after the merge, so the join adds no stall refinement on top of it.
  EXPECT_EQ(mapper_report.num_global_ba, 3);
  ASSERT_EQ(models.size(), 1u);
  const testing::PoseError error = testing::ComparePoses(models[0], p);
  EXPECT_EQ(error.num_registered, 45);
  const double path = (p.cam_from_world.front().Inverse().translation -
                       p.cam_from_world.back().Inverse().translation).norm();
  EXPECT_LT(error.max_centre_error * path, 0.02);
  EXPECT_LT(error.max_rotation_deg, 0.2);

  options.split_at_cuts = false;
  models = RunGlobalMapper(p.input, OneThread(), options, &report, nullptr);
  EXPECT_EQ(report.num_cuts, 1);
  EXPECT_EQ(report.num_pairs_across_cuts, 0);
  EXPECT_GE(report.view_graph.num_dropped_by_triangles, kPairsAcrossCut);
  ASSERT_EQ(models.size(), 2u);
  EXPECT_EQ(models[0].NumRegImages(), 23u);
  EXPECT_EQ(models[1].NumRegImages(), 22u);
  EXPECT_TRUE(models[0].IsRegistered(kCutFrame + 1) && models[1].IsRegistered(1));
}

// A stop asked while mapping (Ctrl-C) ends the mapping at the next stage with Cancelled; the
// hooks are polled between every stage.
TEST(GlobalMapper, StopsAtTheNextStageWhenAsked) {
  const MapperProblem p = NoisyWalkBack(0.5, 0);
  for (int stop_at_poll : {1, 3, 5}) {
    int polls = 0;
    RunHooks hooks;
    hooks.stop_requested = [&] { return ++polls >= stop_at_poll; };
    EXPECT_THROW(RunGlobalMapper(p.input, OneThread(), GlobalMapperOptions(), nullptr, nullptr,
                                 &hooks),
                 Cancelled)
        << "stop at poll " << stop_at_poll;
    EXPECT_EQ(polls, stop_at_poll);
  }
  int polls = 0;
  RunHooks counting;
  counting.stop_requested = [&] { return ++polls < 0; };
  EXPECT_EQ(RunGlobalMapper(p.input, OneThread(), GlobalMapperOptions(), nullptr, nullptr,
                            &counting)
                .size(),
            1u);
  EXPECT_EQ(polls, 5);  // view graph, rotations, positions, one loose and one refining bundle
}

TEST(GlobalMapper, OptionsAreChecked) {
  GlobalMapperOptions options;
  options.max_rotation_error_deg = 0.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.min_track_length = 1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.loose_error_factor = 0.5;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.max_observations_per_track = 1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.loose_settle_tolerance = -1e-3;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.num_refinement_rounds = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.positioning.max_num_iterations = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.max_step_ratio = 1.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options = {};
  options.max_off_observation_fraction = 0.0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  EXPECT_NO_THROW(GlobalMapperOptions().Check());
}

// A model of the walk at its true poses has no jump in its path; the same with the frames
// from the 20th on moved far off (the scale lost between two parts, as global positioning
// did on fox) is counted as broken, and the jump named.
TEST(GlobalMapper, PathJumpsAreReported) {
  MapperProblemOptions problem_options;
  problem_options.num_frames = 30;
  const MapperProblem p = MakeMapperProblem(problem_options);
  Reconstruction model = EmptyReconstruction(p.input);
  for (size_t k = 0; k < p.input.frames.size(); ++k) {
    const image_t id = p.input.frames[k].image_id;
    model.GetImage(id).cam_from_world = p.cam_from_world[k];
    model.RegisterImage(id);
  }
  GlobalMapperReport report;
  CheckPathJumps(p.input, {model}, GlobalMapperOptions(), &report);
  EXPECT_GT(report.largest_step_ratio, 0.0);
  EXPECT_LT(report.largest_step_ratio, 3.0);
  EXPECT_EQ(report.num_broken_models, 0);

  for (size_t k = 20; k < p.input.frames.size(); ++k) {
    Rigid3d& pose = model.GetImage(p.input.frames[k].image_id).cam_from_world;
    pose.translation -= pose.rotation * Eigen::Vector3d(100.0, 0.0, 0.0);  // centre + 100 x
  }
  CheckPathJumps(p.input, {model}, GlobalMapperOptions(), &report);
  EXPECT_GT(report.largest_step_ratio, 50.0);
  EXPECT_EQ(report.num_broken_models, 1);
  EXPECT_EQ(report.largest_step_from, p.input.frames[19].name);
  EXPECT_EQ(report.largest_step_to, p.input.frames[20].name);
}

// Positioning that leaves many observations off (wrong matches, as repeated structure gives)
// counts the component as likely bent; the same walk with its keypoints where they belong
// does not.
TEST(GlobalMapper, PositioningWithManyWrongObservationsIsReportedAsBent) {
  MapperProblem p = NoisyWalkBack(0.3, 0);
  GlobalMapperReport report;
  RunGlobalMapper(p.input, OneThread(), GlobalMapperOptions(), &report, nullptr);
  EXPECT_EQ(report.num_bent_components, 0);
  EXPECT_LT(report.positioning.num_large_angle_observations,
            0.02 * report.positioning.num_observations);

  // Every third keypoint 50 px off (about 5 deg for this camera): a third of the tracks'
  // observations point elsewhere.
  for (MapperFrame& frame : p.input.frames) {
    for (size_t k = 0; k < frame.points2D.size(); k += 3) {
      frame.points2D[k] += Eigen::Vector2d(40.0, 30.0);
    }
  }
  EXPECT_FALSE(
      RunGlobalMapper(p.input, OneThread(), GlobalMapperOptions(), &report, nullptr).empty());
  EXPECT_EQ(report.num_bent_components, 1);
  EXPECT_TRUE(report.Doubtful());
  EXPECT_GT(report.positioning.num_large_angle_observations,
            GlobalMapperOptions().max_off_observation_fraction *
                report.positioning.num_observations);

  // For a caller that maps a bent video otherwise: no bundles, no model.
  GlobalMapperOptions stop;
  stop.stop_when_bent = true;
  EXPECT_TRUE(RunGlobalMapper(p.input, OneThread(), stop, &report, nullptr).empty());
  EXPECT_EQ(report.num_bent_components, 1);
  EXPECT_EQ(report.seconds_bundles, 0.0);
}

}  // namespace
}  // namespace loopsfm
