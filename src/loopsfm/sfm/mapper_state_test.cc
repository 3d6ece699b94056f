#include "loopsfm/sfm/mapper_state.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <unordered_map>
#include <unordered_set>

#include "loopsfm/sfm/loop_test_problem.h"
#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {

using testing::MakeMapperProblem;
using testing::MapperProblem;
using testing::MapperProblemOptions;

// Registers frames [begin, end) at their true poses, the ones from `shifted_from` on moved
// by `shift` (a drifted part of the path).
void RegisterAtTruth(const MapperProblem& p, MapperState& state, int begin, int end,
                     int shifted_from = 1 << 30,
                     const Eigen::Vector3d& shift = Eigen::Vector3d::Zero()) {
  for (int i = begin; i < end; ++i) {
    const image_t id = p.input.frames[i].image_id;
    Rigid3d pose = p.cam_from_world[i];
    if (i >= shifted_from) pose.translation -= pose.rotation * shift;
    state.reconstruction().GetImage(id).cam_from_world = pose;
    state.reconstruction().RegisterImage(id);
    state.TriangulateImage(id);
  }
}

int TracksWithSeveralPoints(const MapperState& state) {
  int count = 0;
  for (size_t t = 0; t < state.input().tracks.size(); ++t) {
    count += state.PointsOfTrack(static_cast<int>(t)).size() > 1;
  }
  return count;
}

MapperProblemOptions SmallProblem() {
  MapperProblemOptions options;
  options.num_frames = 8;
  options.overlap = 7;
  options.num_points = 1500;
  return options;
}

TEST(MapperState, ObservationsThatDoNotFitStartAnotherPointOfTheirTrack) {
  const MapperProblem p = MakeMapperProblem(SmallProblem());
  IncrementalMapperOptions options;
  // Consistent poses: one point per track, every registered observation used.
  {
    MapperState state(p.input, options);
    RegisterAtTruth(p, state, 0, 8);
    EXPECT_EQ(TracksWithSeveralPoints(state), 0);
    const size_t observations = state.reconstruction().ComputeNumObservations();
    size_t track_observations = 0;
    for (const Track& t : p.input.tracks) track_observations += t.Length();
    EXPECT_GT(observations, 0.95 * track_observations);
  }
  // Frames 4..7 drifted by 0.5 m: tracks across the cut get one point per consistent part
  // instead of losing the recent end.
  MapperState state(p.input, options);
  RegisterAtTruth(p, state, 0, 8, 4, Eigen::Vector3d(0.5, 0, 0));
  const int split = TracksWithSeveralPoints(state);
  EXPECT_GT(split, 200);
  for (size_t t = 0; t < p.input.tracks.size(); ++t) {
    for (point3D_t id : state.PointsOfTrack(static_cast<int>(t))) {
      EXPECT_EQ(state.TrackOfPoint(id), static_cast<int>(t));
      // Every point explains all its observations (a two-view point may straddle the cut:
      // two rays always meet somewhere, the shift only moves it in depth).
      for (const TrackElement& el : state.reconstruction().GetPoint3D(id).track.elements) {
        EXPECT_LE(state.ReprojectionErrorPx(state.reconstruction().GetPoint3D(id).xyz, el),
                  options.max_reproj_error_px);
      }
    }
  }
  // Once the poses agree again, points of one track merge back.
  for (int i = 4; i < 8; ++i) {
    state.reconstruction().GetImage(p.input.frames[i].image_id).cam_from_world = p.cam_from_world[i];
  }
  state.RetriangulateAll();
  EXPECT_LT(TracksWithSeveralPoints(state), split / 50 + 1);
}

// Triangulation and FilterPoints test a point's angle alike, over all its views: what one
// makes, the other keeps while the poses stay. Tracks of 60 frames 5 mm apart, 8-12 m from
// the wall, meet at up to 2 degrees over all their views, at about 1 degree at most over 30
// (the filter once looked at a point's first 30 views only, and deleted on every pass the
// points of long tracks that the next triangulation made again: 4,872 observations in
// kitti07_160's final pass, enough to make its refinement bundle twice).
TEST(MapperState, FilteringKeepsWhatTriangulationHasJustMade) {
  MapperProblemOptions problem;
  problem.num_frames = 60;
  problem.overlap = 59;
  problem.step = 0.005;
  problem.num_points = 600;
  const MapperProblem p = MakeMapperProblem(problem);
  IncrementalMapperOptions options;
  MapperState state(p.input, options);
  RegisterAtTruth(p, state, 0, problem.num_frames);
  state.RetriangulateAll();
  const Reconstruction& rec = state.reconstruction();
  size_t long_points = 0;
  for (const auto& [id, point] : rec.Points3D()) long_points += point.track.Length() > 30;
  EXPECT_GT(long_points, 100u);
  const size_t observations = rec.ComputeNumObservations();
  EXPECT_EQ(state.FilterPoints({}), 0u);
  EXPECT_EQ(state.RetriangulateAll(), 0u);
  EXPECT_EQ(rec.ComputeNumObservations(), observations);
}

// A loop's point pairs are fused whether or not all observations fit yet: one point per
// pair with every observation of both, placed between them; points of two tracks are not.
TEST(MapperState, FusesTwoPointsOfOneTrackOnly) {
  const MapperProblem p = MakeMapperProblem(SmallProblem());
  IncrementalMapperOptions options;
  MapperState state(p.input, options);
  RegisterAtTruth(p, state, 0, 8, 4, Eigen::Vector3d(0.5, 0, 0));
  std::vector<point3D_t> pair, others;
  for (size_t t = 0; t < p.input.tracks.size() && pair.empty(); ++t) {
    const std::vector<point3D_t> points = state.PointsOfTrack(static_cast<int>(t));
    if (points.size() == 2) pair = points;
  }
  ASSERT_EQ(pair.size(), 2u);
  for (size_t t = 0; t < p.input.tracks.size() && others.size() < 2; ++t) {
    const std::vector<point3D_t> points = state.PointsOfTrack(static_cast<int>(t));
    if (points.size() == 1 && points[0] != pair[0] && points[0] != pair[1]) {
      others.push_back(points[0]);
    }
  }
  ASSERT_EQ(others.size(), 2u);
  const Reconstruction& rec = state.reconstruction();
  const size_t points_before = rec.NumPoints3D();
  EXPECT_EQ(state.FusePoints(others[0], others[1]), kInvalidPoint3DId);
  EXPECT_EQ(state.FusePoints(pair[0], pair[0]), kInvalidPoint3DId);
  EXPECT_EQ(rec.NumPoints3D(), points_before);

  const size_t observations = rec.GetPoint3D(pair[0]).track.Length() +
                              rec.GetPoint3D(pair[1]).track.Length();
  const int track = state.TrackOfPoint(pair[0]);
  const point3D_t fused = state.FusePoints(pair[0], pair[1]);
  ASSERT_NE(fused, kInvalidPoint3DId);
  EXPECT_EQ(rec.NumPoints3D(), points_before - 1);
  EXPECT_EQ(rec.GetPoint3D(fused).track.Length(), observations);
  EXPECT_EQ(state.PointsOfTrack(track), std::vector<point3D_t>{fused});
}

TEST(MapperState, CountsVisibleTracksOncePerTrack) {
  const MapperProblem p = MakeMapperProblem(SmallProblem());
  IncrementalMapperOptions options;
  MapperState state(p.input, options);
  RegisterAtTruth(p, state, 0, 3);
  const auto visible = state.CountVisibleTracks();
  // Frame 3 sees the tracks with a point that contain it.
  size_t expected = 0;
  for (size_t t = 0; t < p.input.tracks.size(); ++t) {
    if (state.PointsOfTrack(static_cast<int>(t)).empty()) continue;
    for (const TrackElement& el : p.input.tracks[t].elements) expected += el.image_id == 4;
  }
  ASSERT_GT(expected, 100u);
  EXPECT_EQ(visible.at(4), expected);
  EXPECT_EQ(visible.count(1), 0u);  // registered
}

// The counts kept from the model's link changes agree with a walk over every point after each
// kind of change: registration with triangulation, drifted frames (tracks split into several
// points), filtering, points fused, a frame deregistered, retriangulation, and a model
// restored from a checkpoint.
TEST(MapperState, VisibleTrackCountsFollowEveryChangeOfTheModel) {
  const MapperProblem p = MakeMapperProblem(SmallProblem());
  IncrementalMapperOptions options;
  MapperState state(p.input, options);
  auto expect_agree = [&](const char* after) {
    const auto kept = state.CountVisibleTracks();
    EXPECT_EQ(kept, state.CountVisibleTracksByScan()) << "after " << after;
    return kept.size();
  };
  expect_agree("nothing");
  RegisterAtTruth(p, state, 0, 3);
  EXPECT_GT(expect_agree("registering frames 0-2"), 0u);
  RegisterAtTruth(p, state, 3, 7, 5, Eigen::Vector3d(0.5, 0, 0));
  expect_agree("registering drifted frames");
  ASSERT_GT(TracksWithSeveralPoints(state), 0);
  for (int t = 0; t < static_cast<int>(p.input.tracks.size()); ++t) {
    const std::vector<point3D_t> points = state.PointsOfTrack(t);
    if (points.size() >= 2) state.FusePoints(points[0], points[1]);
  }
  expect_agree("fusing points");
  options.max_reproj_error_px = 0.5;  // the state reads the options it was given
  EXPECT_GT(state.FilterPoints({}), 0u);
  options.max_reproj_error_px = IncrementalMapperOptions().max_reproj_error_px;
  expect_agree("filtering");
  state.reconstruction().DeRegisterImage(p.input.frames[1].image_id);
  expect_agree("deregistering a frame");
  state.RetriangulateAll();
  expect_agree("retriangulating");
  state.SetGauge(p.input.frames[0].image_id, p.input.frames[2].image_id);
  MapperState restored(p.input, options);
  restored.Restore(state.Save());
  EXPECT_EQ(restored.CountVisibleTracks(), restored.CountVisibleTracksByScan());
  EXPECT_EQ(restored.CountVisibleTracks(), state.CountVisibleTracks());
}

}  // namespace
}  // namespace loopsfm

namespace loopsfm {
namespace {

// A frame that also sees a twin of what an earlier frame saw (an identical facade further
// along): a false verified pair links its twin keypoints to frame `twin`'s tracks, and its
// true link to the model is a thinned pair with the previous frame, so the twin
// correspondences outnumber the true ones.
struct TwinProblem {
  MapperProblem p;
  int frame = 0;
  int twin = 0;
};

TwinProblem MakeTwinProblem() {
  MapperProblemOptions options;
  options.num_frames = 20;
  options.overlap = 4;
  TwinProblem t{MakeMapperProblem(options), 16, 3};
  MapperInput& input = t.p.input;
  const image_t frame_id = input.frames[t.frame].image_id;
  // Of the frame's true pairs only the one with the previous frame stays, with 40 % of its
  // matches.
  std::erase_if(input.pairs, [&](const MapperPair& pair) {
    const bool has = pair.pair.image_id1 == frame_id || pair.pair.image_id2 == frame_id;
    const image_t other = pair.pair.image_id1 == frame_id ? pair.pair.image_id2 : pair.pair.image_id1;
    return has && other != input.frames[t.frame - 1].image_id;
  });
  for (MapperPair& pair : input.pairs) {
    if (pair.pair.image_id1 != frame_id && pair.pair.image_id2 != frame_id) continue;
    FeatureMatches& matches = pair.geometry.inlier_matches;
    FeatureMatches kept;
    for (size_t k = 0; k < matches.size(); k += 5) {
      kept.push_back(matches[k]);
      if (k + 1 < matches.size()) kept.push_back(matches[k + 1]);
    }
    matches = kept;
  }
  // The twin view: the keypoints of frame `twin`, seen again by `frame`.
  MapperFrame& frame = input.frames[t.frame];
  const MapperFrame& twin = input.frames[t.twin];
  const point2D_t offset = static_cast<point2D_t>(frame.points2D.size());
  MapperPair false_pair;
  false_pair.pair = ImagePair(twin.image_id, frame.image_id);
  for (point2D_t k = 0; k < twin.points2D.size(); ++k) {
    frame.points2D.push_back(twin.points2D[k]);
    t.p.keypoint_point[t.frame].push_back(-1);
    false_pair.geometry.inlier_matches.push_back({k, offset + k});
  }
  false_pair.geometry.config = TwoViewGeometry::kPlanarOrPanoramic;
  input.pairs.push_back(false_pair);
  testing::RebuildTracks(&input);
  return t;
}

TEST(MapperState, RegistrationKeepsToWhatTheFramesNextInTimeSee) {
  const TwinProblem t = MakeTwinProblem();
  const image_t id = t.p.input.frames[t.frame].image_id;
  auto centre_error = [&](const MapperState& state) {
    return (state.reconstruction().GetImage(id).ProjectionCenter() -
            t.p.cam_from_world[t.frame].Inverse().translation).norm();
  };
  const double step = 0.3;

  // Without the check the twin wins: the frame lands where frame `twin` is.
  IncrementalMapperOptions unchecked;
  unchecked.registration_neighbour_window = 0;
  MapperState fooled(t.p.input, unchecked);
  RegisterAtTruth(t.p, fooled, 0, t.frame);
  Random random(5);
  MapperReport fooled_report;
  ASSERT_TRUE(fooled.RegisterImage(id, random, &fooled_report));
  EXPECT_GT(centre_error(fooled), 0.8 * (t.frame - t.twin) * step)
      << "the problem must tempt the registration to the twin";
  EXPECT_EQ(fooled_report.num_poses_against_neighbours, 0);

  IncrementalMapperOptions options;
  MapperState state(t.p.input, options);
  RegisterAtTruth(t.p, state, 0, t.frame);
  MapperReport report;
  ASSERT_TRUE(state.RegisterImage(id, random, &report));
  EXPECT_LT(centre_error(state), 0.05 * step);
  EXPECT_EQ(report.num_poses_against_neighbours, 1);
  EXPECT_EQ(report.num_poses_from_neighbours, 1);
  // The pose fits the neighbour's points.
  const auto correspondences = state.NeighbourCorrespondences(id);
  EXPECT_GT(correspondences.size(), 100u);
  EXPECT_FALSE(state
                   .AgreementWithNeighbours(
                       id, state.reconstruction().GetImage(id).cam_from_world, correspondences)
                   .Disagrees());
}

// A frame registered on a wrong pose before the frames next to it in time (its few
// correspondences then came from farther frames) goes back to the growth once those frames
// register and show the pose wrong; frames whose pose fits stay.
TEST(MapperState, APoseTheNeighboursLaterContradictIsUndone) {
  MapperProblemOptions problem;
  problem.num_frames = 20;
  problem.overlap = 4;
  const MapperProblem p = MakeMapperProblem(problem);
  auto id = [&](int i) { return p.input.frames[i].image_id; };
  for (const bool wrong : {false, true}) {
    SCOPED_TRACE(wrong ? "wrong pose" : "true pose");
    IncrementalMapperOptions options;
    MapperState state(p.input, options);
    RegisterAtTruth(p, state, 0, 10);
    state.SetGauge(id(0), id(1));
    // Frame 12 first, at its true pose or turned 60 degrees about its centre.
    Rigid3d pose = p.cam_from_world[12];
    if (wrong) {
      const Eigen::Vector3d centre = pose.Inverse().translation;
      pose.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 3, Eigen::Vector3d::UnitY())) *
                      pose.rotation;
      pose.translation = -(pose.rotation * centre);
    }
    Reconstruction& rec = state.reconstruction();
    rec.GetImage(id(12)).cam_from_world = pose;
    rec.RegisterImage(id(12));
    // Then frame 10, next to it (frame 9 was too far to judge it by).
    RegisterAtTruth(p, state, 10, 11);
    MapperReport report;
    const size_t before = rec.NumRegImages();
    const std::vector<image_t> undone = state.UndoPosesAgainstNeighbours(id(10), &report);
    if (wrong) {
      EXPECT_EQ(undone, std::vector<image_t>{id(12)});
      EXPECT_FALSE(rec.IsRegistered(id(12)));
      EXPECT_EQ(report.num_poses_undone_by_neighbours, 1);
    } else {
      EXPECT_TRUE(undone.empty());
      EXPECT_TRUE(rec.IsRegistered(id(12)));
      EXPECT_EQ(report.num_poses_undone_by_neighbours, 0);
    }
    for (int i = 0; i <= 10; ++i) EXPECT_TRUE(rec.IsRegistered(id(i))) << i;
    EXPECT_EQ(rec.NumRegImages(), before - undone.size());
  }
}

// A window refinement moves its frames and their points only: the frames behind it, the
// points only they see, and the cameras stay exactly as they were, and they pull the
// window's frames (moved off their poses here) back where they belong.
TEST(MapperState, WindowRefinementMovesOnlyTheWindowsFrames) {
  const MapperProblem p = MakeMapperProblem({});
  IncrementalMapperOptions options;
  options.num_threads = 1;
  // Asked to refine focal lengths: a window must still leave them alone.
  options.refine_known = {.focal_length = true};
  options.refine_unknown = {.focal_length = true};
  MapperState state(p.input, options);
  const int num_frames = static_cast<int>(p.input.frames.size());
  const int window_begin = num_frames - 10;
  RegisterAtTruth(p, state, 0, num_frames);
  state.SetGauge(p.input.frames[0].image_id, p.input.frames[1].image_id);
  Reconstruction& rec = state.reconstruction();
  std::vector<image_t> window;
  for (int i = window_begin; i < num_frames; ++i) {
    const image_t id = p.input.frames[i].image_id;
    window.push_back(id);
    Rigid3d& pose = rec.GetImage(id).cam_from_world;
    pose.translation += Eigen::Vector3d(0.03, -0.02, 0.04) * ((i % 3) - 1.0);
    pose.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.002, Eigen::Vector3d::UnitY())) *
                    pose.rotation;
  }
  const std::unordered_set<image_t> in_window(window.begin(), window.end());
  std::vector<Rigid3d> before;
  for (const MapperFrame& frame : p.input.frames) {
    before.push_back(rec.GetImage(frame.image_id).cam_from_world);
  }
  std::unordered_map<point3D_t, Eigen::Vector3d> behind;  // points no window frame sees
  for (const auto& [id, point] : rec.Points3D()) {
    const bool seen = std::any_of(
        point.track.elements.begin(), point.track.elements.end(),
        [&](const TrackElement& el) { return in_window.count(el.image_id) > 0; });
    if (!seen) behind[id] = point.xyz;
  }
  ASSERT_GT(behind.size(), 100u);
  const std::vector<double> camera_params = rec.GetCamera(1).params;

  MapperReport report;
  state.WindowRefinement(window, &report);
  EXPECT_GE(report.num_global_ba, 1);
  EXPECT_EQ(report.num_failed_bundles, 0);
  EXPECT_EQ(rec.GetCamera(1).params, camera_params);
  for (int i = 0; i < num_frames; ++i) {
    const Rigid3d& pose = rec.GetImage(p.input.frames[i].image_id).cam_from_world;
    if (i < window_begin) {
      EXPECT_EQ(pose.rotation.coeffs(), before[i].rotation.coeffs()) << i;
      EXPECT_EQ(pose.translation, before[i].translation) << i;
      continue;
    }
    const double error =
        (pose.Inverse().translation - p.cam_from_world[i].Inverse().translation).norm();
    // Moved 0.013 to 0.067 off; the bundle's optimum lies within 0.002 to 0.008 of the
    // truth (a second refinement moves them by less than 3e-4).
    EXPECT_LT(error, 0.01) << i;
  }
  for (const auto& [id, xyz] : behind) {
    ASSERT_TRUE(rec.ExistsPoint3D(id));
    EXPECT_EQ(rec.GetPoint3D(id).xyz, xyz);
  }
}

// A model mapped without the loop pairs (its tracks end where the walk turns back) hands
// its points to a state over every pair: a point is taken where its track is the same in
// both, one of a track the loop pairs joined is not (the track is triangulated again), and
// after RetriangulateAll the model has what a triangulation from scratch gives.
TEST(MapperState, TakesThePointsOfAModelWhereTheLoopPairsLeftTheirTracksAlone) {
  const MapperProblem p = testing::WalkOutAndBack();
  const IncrementalMapperOptions options = testing::LoopOptions();
  const int gap = options.loop_closure.min_frame_gap;
  const MapperInput chain = InputPart(p.input, 0, p.input.frames.size(), gap);
  ASSERT_LT(chain.pairs.size(), p.input.pairs.size());
  MapperState mapped(chain, options);
  RegisterAtTruth(p, mapped, 0, static_cast<int>(p.input.frames.size()));
  const Reconstruction& model = mapped.reconstruction();

  MapperState state(p.input, options);
  ASSERT_EQ(state.TakeFramesOf(model).size(), p.input.frames.size());
  const size_t taken = state.TakePointsOf(model, gap);
  const Reconstruction& rec = state.reconstruction();
  EXPECT_EQ(rec.NumPoints3D(), taken);
  size_t joined_tracks = 0, points_of_joined = 0;
  for (size_t t = 0; t < p.input.tracks.size(); ++t) {
    // Joined: the model's points of the track's observations are of several chain tracks.
    std::unordered_set<int> parts;
    for (const TrackElement& el : p.input.tracks[t].elements) {
      if (mapped.TrackOf(el.image_id, el.point2D_idx) >= 0) {
        parts.insert(mapped.TrackOf(el.image_id, el.point2D_idx));
      }
    }
    if (parts.size() < 2) continue;
    ++joined_tracks;
    points_of_joined += state.PointsOfTrack(static_cast<int>(t)).size();
  }
  EXPECT_GT(joined_tracks, 100u);
  EXPECT_EQ(points_of_joined, 0u);
  EXPECT_GT(taken, model.NumPoints3D() / 3);  // most tracks of this walk are joined
  for (const point3D_t id : rec.Point3DIds()) {
    const Point3D& point = rec.GetPoint3D(id);
    for (const TrackElement& el : point.track.elements) {
      EXPECT_EQ(state.TrackOf(el.image_id, el.point2D_idx), state.TrackOfPoint(point));
      EXPECT_LE(state.ReprojectionErrorPx(point.xyz, el), options.max_reproj_error_px);
    }
  }

  state.RetriangulateAll();
  MapperState fresh(p.input, options);
  fresh.TakeFramesOf(model);
  fresh.RetriangulateAll();
  const double observations = fresh.reconstruction().ComputeNumObservations();
  EXPECT_GT(rec.ComputeNumObservations(), 0.98 * observations);
  EXPECT_LT(rec.ComputeNumObservations(), 1.02 * observations);
  EXPECT_LE(TracksWithSeveralPoints(state), TracksWithSeveralPoints(fresh) + 5);
}

}  // namespace
}  // namespace loopsfm
