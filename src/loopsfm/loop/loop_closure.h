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
// close), and the correction it asks for is plausible as drift (drift_correction.h: small
// against the path walked between the two ends, scale change within bounds), so a repeated
// facade does not close a false loop.
//
// Correction: a Sim3 pose graph (estimators/pose_graph.h) over all registered frames with
// edges between consecutive frames and co-visible pairs (pairs that share points in the
// map, measured as the map has them) and loop edges from the similarity; frames move to
// the optimised poses, each point with a frame that observes it, and a global refinement
// (bundle, re-triangulation that merges points of one track that now agree, filtering)
// fuses the two ends. Mapping then goes on from the consistent map.
#include <deque>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "loopsfm/estimators/pose_graph.h"
#include "loopsfm/loop/drift_correction.h"
#include "loopsfm/math/random.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"
#include "loopsfm/sfm/mapper_checkpoint.h"
#include "loopsfm/sfm/point_alignment.h"

namespace loopsfm {

class MapperState;

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

  // A similarity old_from_recent the window's evidence agrees on: all its correspondences,
  // the window registration each came from, and the inliers of each registration.
  struct Hypothesis {
    std::vector<PointCorrespondence> all;
    std::vector<size_t> frame_of;
    PointAlignment alignment;
    std::vector<int> frame_inliers;
    // The median capture index of the old frames that see the inliers' old points.
    int MedianOldIndex(const std::unordered_map<image_t, int>& frame_index) const;
  };

  // A loop's pose-graph edges, the inlier point pairs behind each, and all its inlier pairs
  // (to be fused).
  struct LoopEdges {
    std::vector<LoopEdge> edges;
    std::vector<int> num_point_pairs;
    std::vector<PointPair> inlier_pairs;
  };

  bool DetectAndClose(MapperState& model, image_t image_id, MapperReport* report);
  // Steps of DetectAndClose. UpdateWindow adds the registration to the window and returns
  // the window's evidence, oldest first, once it is full and no cooldown holds (empty
  // otherwise). Align finds the similarity they agree on, if they do and it is no loop
  // closed already. EdgesOf turns it into pose-graph edges. CorrectOrGather corrects the
  // model (or, without refine, gathers the edges) and reports the loop.
  std::vector<Evidence> UpdateWindow(const MapperState& model, image_t image_id);
  std::optional<Hypothesis> Align(const std::vector<Evidence>& window);
  void WarnIfIntrinsicsLookWrong(const MapperState& model, image_t image_id,
                                 const DriftCorrection& correction);
  LoopEdges EdgesOf(const Reconstruction& rec, const std::vector<Evidence>& window,
                    const Hypothesis& loop) const;
  bool CorrectOrGather(MapperState& model, const LoopEdges& edges, ClosedLoop loop,
                       MapperReport* report);
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
  // Steps of Close: the graph's nodes (the registered frames, also listed in capture order
  // in `ordered`) and edges; the map moved to the optimised nodes from the poses `before`.
  void BuildPoseGraph(const MapperState& model, const std::vector<LoopEdge>& loop_edges,
                      double loop_weight, PoseGraph* graph, std::vector<image_t>* ordered) const;
  void MoveWithGraph(const PoseGraph& graph, const std::map<image_t, Sim3d>& before,
                     Reconstruction* rec) const;

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
