#include "loopsfm/sfm/global_mapper_options.h"

#include "loopsfm/util/errors.h"

namespace loopsfm {

void GlobalMapperOptions::Check() const {
  view_graph.Check();
  verification.Check();
  rotation_averaging.Check();
  positioning.Check();
  LOOPSFM_REQUIRE_OPTION(max_rotation_error_deg > 0.0,
                         "global mapper max_rotation_error_deg must be positive, got {}",
                         max_rotation_error_deg);
  LOOPSFM_REQUIRE_OPTION(min_track_length >= 2,
                         "global mapper min_track_length must be at least 2, got {}",
                         min_track_length);
  LOOPSFM_REQUIRE_OPTION(max_tracks_per_frame > 0,
                         "global mapper max_tracks_per_frame must be positive, got {}",
                         max_tracks_per_frame);
  LOOPSFM_REQUIRE_OPTION(max_observations_per_track >= 2,
                         "global mapper max_observations_per_track must be at least 2, got {}",
                         max_observations_per_track);
  LOOPSFM_REQUIRE_OPTION(loose_error_factor >= 1.0,
                         "global mapper loose_error_factor must be at least 1, got {}",
                         loose_error_factor);
  LOOPSFM_REQUIRE_OPTION(num_loose_rounds >= 0,
                         "global mapper num_loose_rounds must not be negative, got {}",
                         num_loose_rounds);
  LOOPSFM_REQUIRE_OPTION(num_refinement_rounds >= 1,
                         "global mapper num_refinement_rounds must be at least 1, got {}",
                         num_refinement_rounds);
  LOOPSFM_REQUIRE_OPTION(loose_points_per_frame >= 0,
                         "global mapper loose_points_per_frame must not be negative, got {}",
                         loose_points_per_frame);
  LOOPSFM_REQUIRE_OPTION(loose_settle_tolerance >= 0.0,
                         "global mapper loose_settle_tolerance must not be negative, got {}",
                         loose_settle_tolerance);
  LOOPSFM_REQUIRE_OPTION(max_off_observation_fraction > 0.0 && max_off_observation_fraction <= 1.0,
                         "global mapper max_off_observation_fraction must be in (0, 1], got {}",
                         max_off_observation_fraction);
  LOOPSFM_REQUIRE_OPTION(max_step_ratio > 1.0,
                         "global mapper max_step_ratio must be above 1, got {}", max_step_ratio);
  LOOPSFM_REQUIRE_OPTION(min_frame_points >= 0,
                         "global mapper min_frame_points must not be negative, got {}",
                         min_frame_points);
}

}  // namespace loopsfm
