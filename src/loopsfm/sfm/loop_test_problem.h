#pragma once
// A drifted walk out and back for the loop-closing tests (loop/loop_closure_test.cc,
// loop/track_split_test.cc) and the refinement after a correction (mapper_state_drift_test.cc):
// the frames of the walk back registered where drift put them.

#include <algorithm>
#include <map>
#include <string>

#include <gtest/gtest.h>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm::testing {

// 40 frames out along a wall and 40 back beside the first ones.
inline MapperProblem WalkOutAndBack() {
  MapperProblemOptions options;
  options.num_frames = 80;
  options.num_points = 4000;
  options.overlap = 6;
  options.walk_back = true;
  return MakeMapperProblem(options);
}

// Options for the walk: its two ends are 20 frames apart or more; one thread, so runs repeat.
inline IncrementalMapperOptions LoopOptions() {
  IncrementalMapperOptions options;
  options.loop_closure.min_frame_gap = 20;
  options.num_threads = 1;
  return options;
}

// Registers every frame in capture order at its true pose, frames of the walk back moved
// sideways and outwards by drift that grows with each frame (`drift_per_frame` metres), as
// an incremental mapper would have placed them; each frame's tracks are triangulated as it
// comes, so where the walk back meets the first frames' points it makes points of its own.
// With `degrees_per_frame` and `scale_per_frame` the walk back also turns and shrinks or grows
// about the turning frame (a focal length that is off does this): drift as a similarity.
inline void RegisterWithDrift(const MapperProblem& p, MapperState& state, double drift_per_frame,
                              double degrees_per_frame = 0.0, double scale_per_frame = 0.0) {
  const int half = static_cast<int>(p.input.frames.size()) / 2;
  const Eigen::Vector3d pivot = p.cam_from_world[half - 1].Inverse().translation;
  for (size_t i = 0; i < p.input.frames.size(); ++i) {
    const image_t id = p.input.frames[i].image_id;
    Rigid3d pose = p.cam_from_world[i];
    const int steps = std::max(0, static_cast<int>(i) - half + 1);
    const double drift = drift_per_frame * steps;
    pose.translation -= pose.rotation * Eigen::Vector3d(0.3 * drift, drift, 0.5 * drift);
    const Eigen::Quaterniond turn(
        Eigen::AngleAxisd(degrees_per_frame * steps * M_PI / 180.0, Eigen::Vector3d::UnitY()));
    const Eigen::Vector3d centre = pose.Inverse().translation;
    const Eigen::Vector3d moved = pivot + (1.0 + scale_per_frame * steps) * (turn * (centre - pivot));
    pose.rotation = (pose.rotation * turn.inverse()).normalized();
    pose.translation = -(pose.rotation * moved);
    state.reconstruction().GetImage(id).cam_from_world = pose;
    state.reconstruction().RegisterImage(id);
    state.TriangulateImage(id);
  }
  state.SetGauge(p.input.frames[0].image_id, p.input.frames[1].image_id);
}

// The walk back drifted as a focal length a few percent off drifts a lap (drift2): 5 mm
// sideways, a turn of 0.15 degrees and 0.4 % of scale per frame.
inline void RegisterTurnedAndScaled(const MapperProblem& p, MapperState& state) {
  RegisterWithDrift(p, state, 0.005, 0.15, 0.004);
}

// The report's loop links are all of `method`, each from a frame of the walk out to one at
// least min_frame_gap later, and carry `num_point_pairs` pairs in all.
inline void ExpectLinksAcrossTheLoop(const MapperProblem& p, const MapperReport& report,
                                     const std::string& method, int min_frame_gap,
                                     int num_point_pairs) {
  ASSERT_FALSE(report.loop_links.empty());
  std::map<std::string, int> index;
  for (size_t i = 0; i < p.input.frames.size(); ++i) index[p.input.frames[i].name] = static_cast<int>(i);
  int pairs = 0;
  for (const LoopLink& link : report.loop_links) {
    EXPECT_EQ(link.method, method);
    EXPECT_LE(index.at(link.old_frame) + min_frame_gap, index.at(link.recent_frame))
        << link.old_frame << " -> " << link.recent_frame;
    pairs += link.num_point_pairs;
  }
  EXPECT_EQ(pairs, num_point_pairs);
}

}  // namespace loopsfm::testing
