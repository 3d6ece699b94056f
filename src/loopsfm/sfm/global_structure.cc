#include "loopsfm/sfm/global_structure.h"

#include <utility>
#include <vector>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// Frames seeing fewer than min_frame_points points leave the model; returns how many. The
// gauge moves to the first two frames left where it was on one of them.
int DropWeakFrames(const std::vector<image_t>& ordered, int min_frame_points,
                   MapperState* state) {
  Reconstruction& rec = state->reconstruction();
  int dropped = 0;
  std::vector<image_t> left;
  for (const image_t id : ordered) {
    if (!rec.IsRegistered(id)) continue;
    if (static_cast<int>(rec.GetImage(id).num_points3D) < min_frame_points) {
      rec.DeRegisterImage(id);
      ++dropped;
    } else {
      left.push_back(id);
    }
  }
  if (left.size() >= 2 && (!rec.IsRegistered(state->GaugeFirst()) ||
                           !rec.IsRegistered(state->GaugeSecond()))) {
    state->SetGauge(left[0], left[1]);
  }
  return dropped;
}

// Registers the frames of `poses` in `state` at those poses, in capture order, with the
// cameras' intrinsics of `cameras` where given, sets the gauge, and triangulates every
// track. Returns the frames registered, in capture order.
std::vector<image_t> PlaceFrames(const MapperInput& input, const std::map<image_t, Rigid3d>& poses,
                                 const std::vector<Camera>* cameras, MapperState* state) {
  Reconstruction& rec = state->reconstruction();
  if (cameras) {
    for (const Camera& camera : *cameras) rec.GetCamera(camera.camera_id) = camera;
  }
  std::vector<image_t> ordered;
  for (const MapperFrame& frame : input.frames) {
    const auto pose = poses.find(frame.image_id);
    if (pose == poses.end()) continue;
    rec.GetImage(frame.image_id).cam_from_world = pose->second;
    rec.RegisterImage(frame.image_id);
    ordered.push_back(frame.image_id);
  }
  if (ordered.size() < 2) return ordered;
  state->SetGauge(ordered[0], ordered[1]);
  state->RetriangulateAll();
  state->FilterPoints({});
  return ordered;
}

}  // namespace

std::optional<MappedState> LooseBundles(const MapperInput& input,
                                        const IncrementalMapperOptions& mapper_options,
                                        const GlobalMapperOptions& options,
                                        const std::map<image_t, Rigid3d>& poses,
                                        const RunHooks* hooks, GlobalMapperReport* report,
                                        MapperReport* mapper_report) {
  Timer timer;
  IncrementalMapperOptions loose_options = mapper_options;
  loose_options.max_reproj_error_px *= options.loose_error_factor;
  MapperState loose(input, loose_options);
  if (PlaceFrames(input, poses, nullptr, &loose).size() < 2) return std::nullopt;
  report->seconds_triangulation += timer.ElapsedSeconds();
  timer.Restart();
  for (int round = 0; round < options.num_loose_rounds; ++round) {
    ThrowIfStopRequested(hooks, "global mapping (bundles)");
    loose.GlobalRefinement(mapper_report);
  }
  report->seconds_bundles += timer.ElapsedSeconds();
  MappedState state = loose.reconstruction().SaveMapped();
  state.points.clear();
  return state;
}

std::optional<Reconstruction> RefinedModel(const MapperInput& input,
                                           const IncrementalMapperOptions& mapper_options,
                                           const GlobalMapperOptions& options,
                                           const MappedState& loose, const RunHooks* hooks,
                                           GlobalMapperReport* report,
                                           MapperReport* mapper_report) {
  Timer timer;
  std::map<image_t, Rigid3d> poses;
  for (const MappedState::RegisteredImage& image : loose.registered) {
    poses[image.image_id] = image.cam_from_world;
  }
  MapperState state(input, mapper_options);
  const std::vector<image_t> ordered = PlaceFrames(input, poses, &loose.cameras, &state);
  Reconstruction& rec = state.reconstruction();
  report->seconds_triangulation += timer.ElapsedSeconds();
  timer.Restart();
  for (int round = 0; round < options.num_refinement_rounds; ++round) {
    ThrowIfStopRequested(hooks, "global mapping (bundles)");
    state.GlobalRefinement(mapper_report);
  }
  const int dropped = DropWeakFrames(ordered, options.min_frame_points, &state);
  report->num_frames_dropped += dropped;
  if (dropped > 0 && rec.NumRegImages() >= 2) {
    state.GlobalRefinement(mapper_report);
  }
  report->seconds_bundles += timer.ElapsedSeconds();
  if (rec.NumRegImages() < 2) return std::nullopt;
  rec.UpdateReprojectionErrors();
  return std::move(rec);
}

}  // namespace loopsfm
