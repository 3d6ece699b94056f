#include "loopsfm/sfm/mapper_state.h"

#include <gtest/gtest.h>

#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {

using testing::MakeMapperProblem;
using testing::MapperProblem;
using testing::MapperProblemOptions;

// Registers frames [begin, end) at their true poses, the ones from `shifted_from` on moved
// by `shift` (a drifted part of the path).
void RegisterAtTruth(const MapperProblem& p, MapperState& state, int begin, int end,
                     int shifted_from = 1 << 30, const Eigen::Vector3d& shift = {}) {
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

}  // namespace
}  // namespace loopsfm
