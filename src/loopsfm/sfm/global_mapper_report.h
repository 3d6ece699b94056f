#pragma once
// What the global mapper (global_mapper.h) did, stage by stage.

#include <string>
#include <vector>

#include "loopsfm/estimators/global_positioning.h"
#include "loopsfm/estimators/rotation_averaging.h"
#include "loopsfm/matching/view_graph_cleaning.h"

namespace loopsfm {

struct GlobalMapperReport {
  // Verified pairs with a relative pose that entered the view graph; the cuts in the video
  // and the pairs across them, left out of it (GlobalMapperOptions::split_at_cuts).
  int num_view_graph_edges = 0;
  int num_cuts = 0;
  int num_pairs_across_cuts = 0;
  // Planar pairs with two candidate poses, and those that took the homography's
  // (global_view_graph.h).
  int num_planar_pairs = 0;
  int num_planar_poses_from_homography = 0;
  ViewGraphCleaningReport view_graph;
  // Connected components of the cleaned view graph, those mapped (at least min_model_size
  // frames, at most max_num_models), and the frames of the others.
  int num_components = 0;
  int num_components_mapped = 0;
  int num_frames_in_other_components = 0;
  // Of the largest component (the first model).
  RotationAveragingReport rotations;
  // Edges left out after rotation averaging (residual above max_rotation_error_deg), and
  // frames dropped for having no edge left, in all components.
  int num_rotation_outliers = 0;
  int num_frames_without_edges = 0;
  // Tracks that entered global positioning, in all components; the positioning report is
  // the largest component's.
  int num_tracks_positioned = 0;
  GlobalPositioningReport positioning;
  // Components whose positioning left more than GlobalMapperOptions::
  // max_off_observation_fraction of their observations off: likely bent.
  int num_bent_components = 0;
  // Frames dropped after the bundles for seeing too few points, in all models.
  int num_frames_dropped = 0;
  // Frames of the input, and in the models at the end.
  int num_frames = 0;
  int num_registered = 0;
  // The first model's largest step between frames next in capture order, as a multiple of
  // its median step, and the two frames (names); models above
  // GlobalMapperOptions::max_step_ratio are counted as likely broken.
  double largest_step_ratio = 0.0;
  std::string largest_step_from, largest_step_to;
  int num_broken_models = 0;
  // Seconds per stage, over all components.
  double seconds_view_graph = 0.0;
  double seconds_rotations = 0.0;
  double seconds_positioning = 0.0;
  double seconds_triangulation = 0.0;
  double seconds_bundles = 0.0;
  // Joining the models mapped between cuts.
  double seconds_joining = 0.0;

  // Whether a component was likely bent or a model likely broken: the models may be wrong
  // as a whole although every local check passes (the pipeline then maps the video again
  // with the incremental mapper, pipeline/reconstruct.h).
  bool Doubtful() const { return num_bent_components > 0 || num_broken_models > 0; }
  // What a doubtful run's messages call its fault: "bent" where a component was (found
  // first, after positioning), else "broken".
  const char* Fault() const { return num_bent_components > 0 ? "bent" : "broken"; }
};

}  // namespace loopsfm
