#include "loopsfm/loop/drift_correction.h"

#include <algorithm>
#include <limits>

namespace loopsfm {

void KeepPathBeforeLoopClosing(const MapperInput& input, const Reconstruction& reconstruction,
                               MapperReport* report) {
  if (!report->path_before_loop_closing.empty()) return;
  for (const MapperFrame& frame : input.frames) {
    if (!reconstruction.ExistsImage(frame.image_id)) continue;
    const Image& image = reconstruction.GetImage(frame.image_id);
    if (image.registered) {
      report->path_before_loop_closing.push_back({image.name, image.cam_from_world.Inverse()});
    }
  }
}

DriftCorrection MeasureCorrection(const Reconstruction& reconstruction, const MapperInput& input,
                                  const Sim3d& old_from_recent, image_t recent_frame,
                                  int old_index, int recent_index,
                                  const LoopClosureOptions& options) {
  constexpr int kTurningStride = 10;  // captures between the frames whose angle is summed
  double path = 0.0;
  double turning_deg = 0.0;
  const Image* previous = nullptr;
  const Image* anchor = nullptr;  // last frame the turning was summed to
  int anchor_index = 0;
  const int end = std::min(recent_index, static_cast<int>(input.frames.size()) - 1);
  for (int k = std::max(old_index, 0); k <= end; ++k) {
    const Image& image = reconstruction.GetImage(input.frames[k].image_id);
    if (!image.registered) continue;
    if (previous) path += (image.ProjectionCenter() - previous->ProjectionCenter()).norm();
    previous = &image;
    if (!anchor) {
      anchor = &image;
      anchor_index = k;
    } else if (k - anchor_index >= kTurningStride) {
      turning_deg += RotationAngleDegrees(image.cam_from_world.rotation *
                                          anchor->cam_from_world.rotation.inverse());
      anchor = &image;
      anchor_index = k;
    }
  }
  if (anchor && previous != anchor) {
    turning_deg += RotationAngleDegrees(previous->cam_from_world.rotation *
                                        anchor->cam_from_world.rotation.inverse());
  }
  DriftCorrection correction;
  correction.turning_deg = turning_deg;
  correction.rotation_deg = RotationAngleDegrees(old_from_recent.rotation);
  const Eigen::Vector3d centre = reconstruction.GetImage(recent_frame).ProjectionCenter();
  correction.translation = (old_from_recent * centre - centre).norm();
  correction.fraction_of_path =
      path > 0.0 ? correction.translation / path : std::numeric_limits<double>::infinity();
  correction.scale = old_from_recent.scale;
  correction.plausible =
      correction.fraction_of_path <= options.max_correction_fraction_of_path &&
      std::max(correction.scale, 1.0 / correction.scale) <= options.max_correction_scale;
  return correction;
}

}  // namespace loopsfm
