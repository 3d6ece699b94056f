#pragma once
// The options of the global mapper (global_mapper.h).

#include "loopsfm/estimators/global_positioning.h"
#include "loopsfm/estimators/rotation_averaging.h"
#include "loopsfm/matching/geometric_verification.h"
#include "loopsfm/matching/view_graph_cleaning.h"

namespace loopsfm {

struct GlobalMapperOptions {
  // Stage 1: the view graph's edges that disagree around triangles go, what a triangle says
  // weighed by its pairs' inliers. Each connected component left with at least the mapper's
  // min_model_size frames becomes a model of its own, largest first, up to its
  // max_num_models (IncrementalMapperOptions); with view_graph.keep_largest_component, only
  // the largest does.
  ViewGraphCleaningOptions view_graph{.weigh_triangles = true, .keep_largest_component = false};
  // The pairs' verification settings (its inlier threshold), for the poses of planar pairs
  // from their F.
  TwoViewVerificationOptions verification;
  // A planar pair's pose is the one of its two candidates, the homography's decomposition and
  // F's, that more triangles of the view graph agree with (global_view_graph.h); false: F's.
  bool planar_pose_by_triangles = true;
  // Where the video cuts (two frames next in capture order share no verified pair), the pairs
  // across the cut stay out of the view graph, so the frames on either side are mapped
  // apart; where some were left out, the incremental mapper then joins the models by the
  // points they share and registers the frames left (ExtendIncrementalModels), as it would
  // across the cut, and its bundles refine them. No change for a video without cuts.
  bool split_at_cuts = true;
  // Stage 2: every frame's rotation from the relative rotations of the edges kept. Edges
  // whose measured rotation is further than max_rotation_error_deg from the averaged ones
  // are counted as outliers, and frames whose every edge is one are dropped.
  RotationAveragingOptions rotation_averaging;
  double max_rotation_error_deg = 5.0;
  // Stage 3: camera centres and track positions together from the observations' bearings.
  // Tracks seen by at least min_track_length frames of the model enter, longest first,
  // while one of their frames has fewer than max_tracks_per_frame of them, each with at most
  // max_observations_per_track of its observations, spread evenly over the track in capture
  // order (a track that returns on every lap of a walk would otherwise tie dozens of frames
  // to each other in the solve's factorisation). The chained start puts every point where
  // its rays meet, so the re-triangulation and second solve meant for points a random start
  // leaves stranded are off (set retriangulate_points with chained_start off).
  GlobalPositioningOptions positioning{.retriangulate_points = false};
  int min_track_length = 3;
  int max_tracks_per_frame = 100;
  int max_observations_per_track = 10;
  // A component whose positioning leaves more than max_off_observation_fraction of its
  // observations further than positioning.max_angle_error_deg from the positions found is
  // reported as likely bent: that many wrong matches (repeated structure, such as a street
  // of identical buildings, gives them) bend positioning, and the bundles keep the bend
  // (docs/global_mapper).
  double max_off_observation_fraction = 0.12;
  // Stop at the first component found likely bent, before its bundles, with no model at all:
  // for a caller that maps the video otherwise then (pipeline/reconstruct.h).
  bool stop_when_bent = false;
  // Also a term per verified pair with an essential matrix, the direction between its two
  // camera centres as the pair's relative pose gives it (GlobalPositioningOptions::
  // camera_direction_weight weighs it against one point observation).
  bool pair_directions = true;
  // Start from the video's order instead of random positions: consecutive frames one unit
  // apart along their pair's direction, points where their rays from there meet.
  bool chained_start = true;
  // Stage 4: every track triangulated from the poses, then rounds of global bundle
  // adjustment with re-triangulation and filtering (the incremental mapper's global
  // refinement, with its options): first num_loose_rounds accepting reprojection errors up
  // to loose_error_factor times the usual bound (the positions are rough), then, triangulated
  // again under the usual bound, num_refinement_rounds. Frames that see fewer than
  // min_frame_points points after the rounds are dropped from the model, and one more
  // round follows.
  double loose_error_factor = 8.0;
  int num_loose_rounds = 1;
  // The loose rounds only correct the poses for the triangulation after them, so they
  // bundle the points of the longest tracks alone, taken while a frame has fewer than
  // loose_points_per_frame of them (MapperState::LongestTrackPoints); 0: every point, with
  // re-triangulation and filtering as in the refinement rounds. They end once the cameras
  // have settled to loose_settle_tolerance (BundleAdjustmentOptions::settle_tolerance),
  // looser than the refinement rounds' tolerance.
  int loose_points_per_frame = 300;
  double loose_settle_tolerance = 1e-3;
  int num_refinement_rounds = 1;
  int min_frame_points = 15;
  // A model whose path jumps, between two frames next to each other in capture order, by
  // more than max_step_ratio times its median step between such frames is reported as
  // likely broken (global positioning can lose the scale between parts of a video, and the
  // bundles do not always recover it; docs/global_mapper).
  double max_step_ratio = 50.0;
  void Check() const;  // throws InvalidArgument
};

}  // namespace loopsfm
