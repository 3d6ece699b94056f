#pragma once
// The options of the incremental mapper (incremental_mapper.h) and of loop closing
// (loop/loop_closing.h, loop/loop_closure.h, loop/track_split.h).

#include <cstdint>
#include <string>

#include "loopsfm/math/random.h"

namespace loopsfm {

// Which intrinsic parameters of a camera bundle adjustment refines. The focal lengths of a
// model with fx and fy are refined as they are (COLMAP's convention).
struct IntrinsicsRefinement {
  bool focal_length = false;
  bool principal_point = false;
  bool distortion = false;
  bool Any() const { return focal_length || principal_point || distortion; }
  // "focal,principal-point,distortion" (any subset, comma-separated) or "none"; throws
  // InvalidArgument naming the accepted words otherwise.
  static IntrinsicsRefinement Parse(const std::string& text);
  std::string ToString() const;
};

// How loops are closed: none maps exactly as without loop closing; posegraph corrects the
// map while mapping (loop/loop_closure.h); split ties the disagreeing points of split tracks
// together in a bundle adjustment after mapping (loop/track_split.h); both does the two.
enum class LoopClosingMethod { kNone, kPoseGraph, kSplit, kBoth };

// Loop closing (loop/loop_closing.h).
struct LoopClosureOptions {
  LoopClosingMethod method = LoopClosingMethod::kPoseGraph;
  bool CloseWhileMapping() const {
    return method == LoopClosingMethod::kPoseGraph || method == LoopClosingMethod::kBoth;
  }
  bool SplitTracks() const {
    return method == LoopClosingMethod::kSplit || method == LoopClosingMethod::kBoth;
  }
  // Evaluation: map without the pairs between frames min_frame_gap or more apart, then add
  // them and close the loops of the largest model at the end (CloseLoopsAfterMapping), as if
  // they had been found late. Drift then grows unchecked until the end, which shows what
  // loop closing corrects.
  bool withhold_loop_pairs = false;
  // Frames at least this far apart in capture order are two ends of a loop.
  int min_frame_gap = 50;
  // A registration is loop evidence when its frame sees this many recent points whose
  // tracks also hold an old point.
  int min_frame_correspondences = 15;
  // Consecutive registrations with evidence that must agree on one similarity, each with
  // at least min_frame_inliers of its own; over them, at least min_num_inliers inliers and
  // min_inlier_ratio of the correspondences (reprojection threshold in pixels).
  int num_consistent = 3;
  int min_frame_inliers = 8;
  int min_num_inliers = 50;
  double min_inlier_ratio = 0.3;
  double max_reproj_error_px = 8.0;
  // Plausible drift: the correction moves the recent end by at most this fraction of the
  // path walked between the two ends, and scales it by at most this factor (either way).
  // The translation bound refuses look-alike places; the scale bound only alignments no
  // drift could explain, and allows what drift does over several laps
  // (docs/mapper_options.md).
  double max_correction_fraction_of_path = 0.1;
  double max_correction_scale = 3.0;
  // Pose graph: frames sharing this many points are joined by a co-visibility edge; a loop
  // edge weighs this much more than the others (after mapping, the loops corrected together
  // share this weight: each of n loops' edges weighs loop_edge_weight / n).
  int covisibility_min_points = 20;
  double loop_edge_weight = 100.0;
  // Split tracks: weight of a pair's coincidence term against a reprojection error, per
  // pixel of the pair's separation seen from an observer (distance / depth * focal).
  double split_weight = 10.0;
  // Refinement after a pose-graph correction, whose cameras start far from the bundle's
  // optimum (the first step's cost is about 30x the final one): a bundle over the longest
  // tracks only, up to this many points per frame, moves the cameras most of the way at a
  // fraction of the cost; the other points are re-triangulated from the moved cameras (those
  // that no longer fit them dropped), and the full bundle then polishes, ending once no
  // camera moves by more than polish_settle_tolerance of the centres' spread per step.
  // 0 points: full bundle only.
  int refine_points_per_frame = 300;
  double polish_settle_tolerance = 1e-4;
  // After mapping (the gathered loops' one correction), the bundle over the longest tracks
  // ends once a step lowers its cost by less than this fraction: the full bundle polishes
  // after it. While mapping it keeps Ceres' 1e-6, since mapping goes on from the corrected
  // cameras (docs/mapper_options.md).
  double refine_function_tolerance = 1e-4;
  // Split tracks, in that first bundle: up to this many of each group's tied pairs, each
  // weighted to pull as hard as the group's share it stands for.
  int split_refine_ties_per_group = 200;
  void Check() const;
};

struct IncrementalMapperOptions {
  // Initial pair: fewest inlier matches (pairs with half as many are tried when no pair
  // with this many gives a valid start).
  int init_min_num_inliers = 100;
  // Initial pair: largest fraction of its inliers a homography may explain (planar scenes
  // and pure rotations make poor starts; they are tried last).
  double init_max_h_inlier_ratio = 0.5;
  // Initial pair: an inlier is well conditioned when its two-view triangulation angle is
  // at least this (degrees); pairs are ranked by their number of well-conditioned inliers.
  double init_min_tri_angle_deg = 3.0;
  // Initial pair: the two-view model must keep this many points after its bundle
  // adjustment and filtering (half for the relaxed candidates).
  int init_min_num_points = 100;
  // Initial pairs tried, at most, for one model.
  int init_max_trials = 50;
  // Registration: inlier threshold in pixels and fewest inliers / inlier ratio.
  double abs_pose_max_error_px = 8.0;
  int abs_pose_min_num_inliers = 30;
  double abs_pose_min_inlier_ratio = 0.25;
  // Diagnostic: after each registration, a second RANSAC over the correspondences the first
  // rejected; where it finds a pose of its own (as many inliers and as large a ratio as a
  // registration needs), the frame had two plausible poses (MapperReport::registrations).
  // Its random numbers are its own, so the mapping is the same with it or without.
  bool record_alternate_poses = false;
  // A frame that failed to register is tried again once it sees this factor more of the
  // model's tracks, or after the next global bundle adjustment.
  double registration_retry_growth = 1.2;
  // Registration order: frames within this many frames in capture order of a registered one
  // go first (most visible tracks first among them), the others after; 0 ranks all frames by
  // visible tracks alone. A frame far in time from the model that sees many of its tracks
  // may see look-alike structure (identical facades): registered before its neighbours it
  // lands where its twin is, and the model grows on from there. Reached from its
  // neighbours, its true pose has their support.
  int registration_capture_window = 2;
  // A registration's pose must fit the points the frame shares with the registered frames
  // nearest to it in capture order, within this many frames (MapperState::
  // AgreementWithNeighbours); 0 checks nothing.
  int registration_neighbour_window = 10;
  // Triangulation and filtering: reprojection error in pixels, angle in degrees.
  double max_reproj_error_px = 4.0;
  double min_tri_angle_deg = 1.5;
  // Local bundle adjustment: the new frame and this many frames sharing most points with it.
  int local_ba_num_images = 6;
  // Global bundle adjustment when the registered frame count has grown by this fraction.
  // Video frames register in order with a local bundle each, so drift between two global
  // bundles stays small (docs/mapper_options.md).
  double global_ba_growth = 0.5;
  // A growth-triggered global bundle is skipped while the frames not in the model number at
  // most this fraction of it: growth ends with a global bundle anyway (when no frame
  // registers), and it would come within that much growth of the skipped one; otherwise two
  // full bundles of nearly the same model end the mapping whenever the last growth step
  // lands near the end (docs/mapper_options.md). 0: never skip.
  double global_ba_end_margin = 0.1;
  // Growth-triggered global bundles of a video model larger than this many frames are
  // windowed: only the frames registered most recently (this many) move, with the points
  // they observe; the frames behind them stay fixed and anchor those points, and the cameras'
  // intrinsics stay as they are. What is far behind the camera changes little until a loop
  // closes, and a full bundle of the whole model after every growth step costs more with
  // every lap. Such a bundle comes after every half window of new frames (or the growth
  // fraction, whichever is fewer), so each frame moves in two of them. Loop closings,
  // merges and the end of growth still refine the whole model. 0: always the whole model.
  int global_ba_window = 300;
  // What global bundle adjustments refine of cameras without a prior focal length (guessed
  // or self-calibrated), and of cameras with known intrinsics (--intrinsics). Local bundles
  // hold every camera fixed. Focal lengths are refined once a model has 5 frames, the
  // principal point and distortion once it has 10.
  IntrinsicsRefinement refine_unknown = {.focal_length = true, .distortion = true};
  IntrinsicsRefinement refine_known = {};
  // Cameras without a prior focal length: while their focal length is refined, it is held
  // near the one mapping started from (self-calibrated or guessed) by a prior on log f with
  // this standard deviation (estimators/cost_functions/focal_prior.h; 0: none).
  double focal_prior_sigma_log = 0.2;
  // Stop after this many models; models smaller than min_model_size frames are discarded.
  int max_num_models = 10;
  int min_model_size = 3;
  // Model merging: common tracks whose points agree after the similarity, within this
  // reprojection error (pixels, in both models), at least this many and this fraction.
  double merge_max_reproj_error_px = 8.0;
  int merge_min_num_inliers = 30;
  double merge_min_inlier_ratio = 0.3;
  LoopClosureOptions loop_closure;
  // Worker threads for bundle adjustment (0: all cores).
  int num_threads = 0;
  uint64_t seed = kDefaultRandomSeed;
  void Check() const;
};

}  // namespace loopsfm
