#pragma once
// What the incremental mapper did (incremental_mapper.h): counts, times per step, the loops
// it closed, and with record_alternate_poses its registrations.

#include <string>
#include <vector>

#include "loopsfm/scene/dataset_files.h"

namespace loopsfm {

// One loop closed while mapping, for the report.
struct ClosedLoop {
  std::string recent_frame, old_frame;
  int num_correspondences = 0;
  int num_inliers = 0;
  // The correction of the recent end: translation of its newest frame's centre (world
  // units, and as a fraction of the path walked between the two ends), rotation, scale.
  double correction_translation = 0.0;
  double correction_fraction_of_path = 0.0;
  double correction_rotation_deg = 0.0;
  double correction_scale = 1.0;
  // Points of one track that were fused by the refinement after the correction.
  long long num_points_before = 0;
  long long num_points_after = 0;
  double seconds = 0.0;
};

// A registration's pose estimation and, with record_alternate_poses, the second round over
// the correspondences the first rejected (second_* zero where there were too few to try).
struct RegistrationRounds {
  std::string frame;
  int num_correspondences = 0;
  int num_inliers = 0;
  int second_num_correspondences = 0;
  int second_num_inliers = 0;
  bool second_pose_found = false;
  // How far the second pose is from the first: centre distance (model units), rotation.
  double second_centre_distance = 0.0;
  double second_rotation_deg = 0.0;
};

struct MapperReport {
  // Adds another run's counts, times and lists (the mapping of another part of the frames)
  // to these: everything but num_models, num_registered and path_before_loop_closing, which
  // only the caller knows how to combine.
  void Add(const MapperReport& other);

  int num_models = 0;
  int num_registered = 0;
  // Initial pairs tried (two-view models built) and those that passed validation.
  int num_init_trials = 0;
  int num_init_accepted = 0;
  // Registrations that succeeded on a later try, after failing before.
  int num_registered_on_retry = 0;
  // Models merged into another, and grown models discarded as too small.
  int num_models_merged = 0;
  int num_models_discarded = 0;
  int num_local_ba = 0;
  int num_global_ba = 0;
  // Summed over all local / global bundles: solver iterations and residual blocks.
  long long num_local_ba_iterations = 0;
  long long num_local_ba_residuals = 0;
  long long num_global_ba_iterations = 0;
  long long num_global_ba_residuals = 0;
  // Bundle adjustments whose solver failed (the model kept its previous state), and
  // registrations whose pose refinement failed (the RANSAC pose was used).
  int num_failed_bundles = 0;
  int num_failed_pose_refinements = 0;
  // Registrations whose first pose disagreed with the frames next to it in capture order,
  // and those of them registered with a pose from the points those frames see.
  int num_poses_against_neighbours = 0;
  int num_poses_from_neighbours = 0;
  // Registered frames deregistered when a later frame next to them showed their pose wrong
  // (MapperState::UndoPosesAgainstNeighbours), to be registered again.
  int num_poses_undone_by_neighbours = 0;
  double seconds_registration = 0.0;
  double seconds_triangulation = 0.0;
  double seconds_local_ba = 0.0;
  double seconds_global_ba = 0.0;
  double seconds_merging = 0.0;
  // Handing the mapper's state to MapperCheckpointing::save (copied and written).
  double seconds_checkpoints = 0.0;
  // Loops closed while mapping, and windows of consistent evidence refused as implausible
  // drift (too large a correction).
  std::vector<ClosedLoop> loops_closed;
  int num_loops_refused = 0;
  // Looking for loop evidence after each registration, and correcting the loops found.
  double seconds_loop_detection = 0.0;
  double seconds_loop_closing = 0.0;
  // Track splitting after mapping: groups of split pairs (one per stretch of a loop) that
  // one similarity explains and that were tied together, those refused as implausible, the
  // pairs tied, and the time taken (finding them and the bundle adjustments).
  // The camera path (registered frames in capture order, world_from_cam) just before the
  // first loop correction (pose graph or split tracks), for before / after plots.
  std::vector<TrajectoryEntry> path_before_loop_closing;
  int num_split_groups = 0;
  int num_split_groups_refused = 0;
  int num_split_pairs = 0;
  double seconds_split = 0.0;
  // The frames each loop correction tied together (pose graph: each loop edge; split
  // tracks: the median observers in capture order of each tied pair's old and recent point).
  std::vector<LoopLink> loop_links;
  // With record_alternate_poses: each successful registration, in the order they happened
  // (a frame registered again after a failed bundle appears again).
  std::vector<RegistrationRounds> registrations;
};

}  // namespace loopsfm
