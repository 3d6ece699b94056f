#pragma once
// Loop closing while mapping (pose graph).
//
// Detection in the map: a track may hold several 3D points (mapper_state.h). When the
// camera comes back to a place after drift, the frame just registered observes points
// whose tracks hold both a recent point (seen only by frames near it in time) and an old
// point (seen only by frames far back), which disagree. Either the frame still follows the
// drifted recent map and its observations did not fit the old points, or its registration
// jumped onto the old map and the frames just before it hold the recent points: both are
// loop evidence, pairs of (recent, old) points. A similarity
// old_from_recent is estimated from them (LO-RANSAC, point_alignment.h), and a loop is
// accepted only when it is supported by several consecutive registrations (each with
// inliers of its own: ORB-SLAM's consecutive-coincidence test), most of its inliers do not
// already agree as they are (points that missed merging by a few pixels are no loop to
// close), and the correction it asks for is plausible as drift (small against the path walked between the two ends, scale
// change within bounds), so a repeated facade does not close a false loop.
//
// Correction: a Sim3 pose graph (estimators/pose_graph.h) over all registered frames with
// edges between consecutive frames and co-visible pairs (pairs that share points in the
// map, measured as the map has them) and loop edges from the similarity; frames move to
// the optimised poses, each point with a frame that observes it, and a global refinement
// (bundle, re-triangulation that merges points of one track that now agree, filtering)
// fuses the two ends. Mapping then goes on from the consistent map.
#include <deque>
#include <string>
#include <unordered_map>
#include <vector>

#include "loopsfm/math/random.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"
#include "loopsfm/sfm/mapper_checkpoint.h"
#include "loopsfm/sfm/point_alignment.h"

namespace loopsfm {

class MapperState;

// The input without the pairs between frames min_frame_gap or more apart in capture order,
// tracks rebuilt from the rest: what a mapper sees when the loop pairs are withheld.
MapperInput WithoutLoopPairs(const MapperInput& input, int min_frame_gap);

// Loop closing on a finished model, for loop pairs that come after mapping: the model's
// frames and cameras are taken into a state over `input` (which holds the loop pairs), its
// tracks are triangulated frame by frame in capture order (the two ends of a drifted loop
// get points of their own), the frames are offered to the loop closer in capture order, and
// a global refinement ends it. With loop closing disabled only the triangulation and the
// refinement run: what a global bundle adjustment makes of the loop pairs on its own.
Reconstruction CloseLoopsAfterMapping(const MapperInput& input, const Reconstruction& model,
                                      const IncrementalMapperOptions& options,
                                      MapperReport* report);

// What a similarity old_from_recent asks of the recent end of a loop: how far it moves the
// centre of `recent_frame`, also as a fraction of the path walked (registered frames in
// capture order) between capture indices old_index and recent_index, its rotation and
// scale; and whether that is plausible as drift under the options' bounds. Also how far the
// camera turned along the way (angles between registered frames about ten captures apart,
// summed, so shake does not add up).
struct DriftCorrection {
  double translation = 0.0;
  double fraction_of_path = 0.0;
  double rotation_deg = 0.0;
  double scale = 1.0;
  double turning_deg = 0.0;
  bool plausible = false;
  // A rotation that large a share of the turning is what intrinsics that are off make: a
  // focal length e % off can measure turns up to about e % short or long, and a lap's turns
  // add up (drift2, focal 5 % short: 18.6 deg over 411 deg). Other drift stays well under
  // that, and so may a wrong focal length where the turns are made in place (block.mp4,
  // focal 4 % long: 1.3 to 2.0 deg over 360 deg, no warning).
  bool SuggestsWrongIntrinsics() const {
    return turning_deg >= 90.0 && rotation_deg >= 0.02 * turning_deg;
  }
};
DriftCorrection MeasureCorrection(const Reconstruction& reconstruction, const MapperInput& input,
                                  const Sim3d& old_from_recent, image_t recent_frame,
                                  int old_index, int recent_index,
                                  const LoopClosureOptions& options);

// Keeps the path of `reconstruction` in report->path_before_loop_closing unless a path is
// kept there already (the first correction's "before").
void KeepPathBeforeLoopClosing(const MapperInput& input, const Reconstruction& reconstruction,
                               MapperReport* report);

class LoopCloser {
 public:
  // refine (while mapping): each loop found is corrected at once (pose graph, then a global
  // refinement) so mapping can go on from a consistent map. Otherwise (after mapping, every
  // frame already registered) the loops found are gathered and corrected together by
  // CloseGathered: one pose graph over all their edges, then the points of each track that
  // now agree are merged, and the caller refines once at the end. Without refine the model
  // must not change between AfterRegistration calls: the evidence of the window's earlier
  // registrations is kept from their own calls, not collected again.
  LoopCloser(const MapperInput& input, const LoopClosureOptions& options,
             uint64_t seed = kDefaultRandomSeed, bool refine = true);

  // Call after `image_id` was registered (and its local bundle ran). Collects its loop
  // evidence and, when a consistent loop is found, corrects the model (pose graph, global
  // refinement) or, without refine, gathers it. Returns true when it corrected the model.
  // Draws from its own random numbers, so a mapping where no loop is closed is the same as
  // one without loop closing.
  bool AfterRegistration(MapperState& model, image_t image_id, MapperReport* report);

  // Corrects the model for every loop gathered so far, in one pose graph; returns true when
  // there was one and the pose graph succeeded.
  bool CloseGathered(MapperState& model, MapperReport* report);

  // Its state between registrations (random numbers, evidence window, cooldown), into and
  // from a mapper checkpoint. Restore throws InputError for a state that is not one.
  void Save(MapperCheckpoint* checkpoint) const;
  void Restore(const MapperCheckpoint& checkpoint);

 private:
  struct Evidence {
    image_t image_id = kInvalidImageId;
    // src: the recent point of a track; dst: its old point.
    std::vector<PointCorrespondence> correspondences;
    std::vector<point3D_t> recent_points, old_points;
  };

  // An edge between the two ends of a loop: the old frame's pose relative to the recent
  // one's as the loop's similarity says it should be (the pose graph's measurement).
  struct LoopEdge {
    image_t old_id = kInvalidImageId;
    image_t recent_id = kInvalidImageId;
    Sim3d measured;
  };

  // Two points of one track, at the old end and at the recent end of a loop.
  struct PointPair {
    point3D_t old_id = kInvalidPoint3DId;
    point3D_t recent_id = kInvalidPoint3DId;
  };

  bool DetectAndClose(MapperState& model, image_t image_id, MapperReport* report);
  void ClearWindow() {
    window_.clear();
    window_evidence_.clear();
  }
  Evidence CollectEvidence(const MapperState& model, image_t image_id) const;
  // Pose graph over the registered frames and `loop_edges` (each of weight `loop_weight`),
  // points moved with their frames, the pairs in `fuse` fused, then the tracks
  // re-triangulated and, with refine_, the model refined. False when the graph failed.
  bool Close(MapperState& model, const std::vector<LoopEdge>& loop_edges, double loop_weight,
             const std::vector<PointPair>& fuse, MapperReport* report);

  const MapperInput& input_;
  const LoopClosureOptions& options_;
  Random random_;
  bool refine_ = true;
  // Capture index of each frame.
  std::unordered_map<image_t, int> frame_index_;
  // The latest registrations that had evidence, oldest first.
  std::deque<image_t> window_;
  // Without refine: their evidence, as collected at their calls (the same window).
  std::deque<Evidence> window_evidence_;
  // Registrations left before another loop may be closed.
  int cooldown_ = 0;
  // The warning that the given intrinsics look wrong was given.
  bool warned_intrinsics_ = false;
  // Without refine: the edges of the loops found and not yet corrected, and their entries in
  // the report's loops_closed.
  std::vector<LoopEdge> gathered_;
  std::vector<size_t> gathered_loops_;
};

}  // namespace loopsfm
