#pragma once
// What the global mapper (global_mapper.h) starts from: the relative pose of every verified
// pair, and the places where the video cuts.
//
// A planar pair (a homography explains most of its inliers) has two candidate poses: the
// homography's decomposition, and the essential matrix's from its F. Neither is right
// everywhere: where the baseline is short against the depth the decomposition can pick the
// wrong solution, and on a facade filmed head on F is poorly determined (docs/global_mapper).
// The other pairs decide: each planar pair takes the candidate that more triangles of the
// view graph agree with (the loop rotation within the view graph cleaning's bound, with
// either candidate of the triangle's other planar pairs), F's on a tie.
//
// A cut is a place where two frames next in capture order share no verified pair: an edited
// video, dropped frames, a turn faster than the frame rate. The only pairs across it are
// long ones, whose two-view rotations can be far off, and rotation averaging has nothing
// better to turn the two sides by.
//
//   const FrameLookup lookup(input);
//   const std::vector<PairPose> poses = PairPoses(input, lookup, options, &report);
//   const std::vector<int> run = RunsBetweenCuts(input);  // per frame, in capture order

#include <unordered_map>
#include <vector>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/sfm/global_mapper_options.h"
#include "loopsfm/sfm/global_mapper_report.h"
#include "loopsfm/sfm/mapper_input.h"

namespace loopsfm {

// The input's frames and cameras by id; it points into the input, which must outlive it.
class FrameLookup {
 public:
  explicit FrameLookup(const MapperInput& input);
  const MapperFrame& Frame(image_t id) const { return *frames_.at(id); }
  int CaptureIndex(image_t id) const { return capture_index_.at(id); }
  const Camera& CameraOf(image_t id) const { return *cameras_.at(Frame(id).camera_id); }

 private:
  std::unordered_map<image_t, const MapperFrame*> frames_;
  std::unordered_map<image_t, int> capture_index_;
  std::unordered_map<camera_t, const Camera*> cameras_;
};

// The relative pose of a verified pair, as the global mapper uses it.
struct PairPose {
  image_t image_id1 = kInvalidImageId;
  image_t image_id2 = kInvalidImageId;
  Rigid3d cam2_from_cam1;
  // The translation's direction is known (zero for a panoramic pair).
  bool has_translation = false;
  double weight = 0.0;  // inliers
};

// Every verified pair with a relative pose, in the input's order; a planar pair's as above
// (with options.planar_pose_by_triangles; F's otherwise). The report gets the number of
// planar pairs and of those that took the homography's pose.
std::vector<PairPose> PairPoses(const MapperInput& input, const FrameLookup& lookup,
                                const GlobalMapperOptions& options, GlobalMapperReport* report);

// For each frame of the input, in capture order, the index of its run: the frames between
// two cuts (0 up to the first cut, and so on).
std::vector<int> RunsBetweenCuts(const MapperInput& input);

}  // namespace loopsfm
