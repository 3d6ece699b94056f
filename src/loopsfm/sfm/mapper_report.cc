#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

void MapperReport::Add(const MapperReport& other) {
  num_init_trials += other.num_init_trials;
  num_init_accepted += other.num_init_accepted;
  num_registered_on_retry += other.num_registered_on_retry;
  num_models_merged += other.num_models_merged;
  num_models_discarded += other.num_models_discarded;
  num_local_ba += other.num_local_ba;
  num_global_ba += other.num_global_ba;
  num_local_ba_iterations += other.num_local_ba_iterations;
  num_local_ba_residuals += other.num_local_ba_residuals;
  num_global_ba_iterations += other.num_global_ba_iterations;
  num_global_ba_residuals += other.num_global_ba_residuals;
  num_failed_bundles += other.num_failed_bundles;
  num_failed_pose_refinements += other.num_failed_pose_refinements;
  num_poses_against_neighbours += other.num_poses_against_neighbours;
  num_poses_undone_by_neighbours += other.num_poses_undone_by_neighbours;
  num_poses_from_neighbours += other.num_poses_from_neighbours;
  seconds_registration += other.seconds_registration;
  seconds_triangulation += other.seconds_triangulation;
  seconds_local_ba += other.seconds_local_ba;
  seconds_global_ba += other.seconds_global_ba;
  seconds_merging += other.seconds_merging;
  seconds_checkpoints += other.seconds_checkpoints;
  loops_closed.insert(loops_closed.end(), other.loops_closed.begin(), other.loops_closed.end());
  num_loops_refused += other.num_loops_refused;
  seconds_loop_detection += other.seconds_loop_detection;
  seconds_loop_closing += other.seconds_loop_closing;
  num_split_groups += other.num_split_groups;
  num_split_groups_refused += other.num_split_groups_refused;
  num_split_pairs += other.num_split_pairs;
  seconds_split += other.seconds_split;
  loop_links.insert(loop_links.end(), other.loop_links.begin(), other.loop_links.end());
  registrations.insert(registrations.end(), other.registrations.begin(),
                       other.registrations.end());
}

}  // namespace loopsfm
