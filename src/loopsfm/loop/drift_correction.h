#pragma once
// What a loop correction asks of a drifted path, and whether that is plausible as drift
// (the pose-graph loop closer, loop_closure.h, and split tracks, track_split.h).

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

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
  // add up. Other drift stays well under it (the cases measured: docs/mapper_options.md).
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

}  // namespace loopsfm
