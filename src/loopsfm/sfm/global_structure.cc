#include "loopsfm/sfm/global_structure.h"

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/logging.h"
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

struct PathJump {
  double ratio = 0.0;
  image_t from = kInvalidImageId, to = kInvalidImageId;
};

// The model's largest step between registered frames next in capture order, as a multiple
// of the median step, with the two frames; nullopt with fewer than three frames or no motion.
std::optional<PathJump> LargestPathJump(const MapperInput& input, const Reconstruction& model) {
  std::vector<std::pair<image_t, Eigen::Vector3d>> centres;
  for (const MapperFrame& frame : input.frames) {
    if (model.IsRegistered(frame.image_id)) {
      centres.push_back({frame.image_id, model.GetImage(frame.image_id).ProjectionCenter()});
    }
  }
  if (centres.size() < 3) return std::nullopt;
  std::vector<double> steps;
  PathJump jump;
  double largest = 0.0;
  for (size_t k = 1; k < centres.size(); ++k) {
    steps.push_back((centres[k].second - centres[k - 1].second).norm());
    if (steps.back() > largest) {
      largest = steps.back();
      jump.from = centres[k - 1].first;
      jump.to = centres[k].first;
    }
  }
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  const double median = steps[steps.size() / 2];
  if (!(median > 0.0)) return std::nullopt;
  jump.ratio = largest / median;
  return jump;
}

}  // namespace

void CheckPathJumps(const MapperInput& input, const std::vector<Reconstruction>& models,
                    const GlobalMapperOptions& options, GlobalMapperReport* report) {
  report->num_broken_models = 0;
  for (size_t m = 0; m < models.size(); ++m) {
    const std::optional<PathJump> jump = LargestPathJump(input, models[m]);
    if (!jump) continue;
    const std::string from = models[m].GetImage(jump->from).name;
    const std::string to = models[m].GetImage(jump->to).name;
    if (m == 0) {
      report->largest_step_ratio = jump->ratio;
      report->largest_step_from = from;
      report->largest_step_to = to;
    }
    if (jump->ratio <= options.max_step_ratio) continue;
    ++report->num_broken_models;
    spdlog::warn("global mapper: model {} is likely broken: its path jumps between {} and {} "
                 "by {:.0f} times its median step between frames (global positioning lost the "
                 "scale between parts of the video)",
                 m, from, to, jump->ratio);
  }
}

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
    if (options.loose_points_per_frame > 0) {
      MapperState::GlobalBundleScope scope;
      scope.points = loose.LongestTrackPoints(options.loose_points_per_frame);
      scope.settle_tolerance = options.loose_settle_tolerance;
      loose.GlobalBundle(mapper_report, scope);
    } else {
      loose.GlobalRefinement(mapper_report, options.loose_settle_tolerance);
    }
  }
  report->seconds_bundles += timer.ElapsedSeconds();
  MappedState state = loose.reconstruction().SaveMapped();
  state.points.clear();
  return state;
}

std::optional<Reconstruction> RefinedModel(const MapperInput& input,
                                           const IncrementalMapperOptions& mapper_options,
                                           const GlobalMapperOptions& options,
                                           const MappedState& loose, bool refine,
                                           const RunHooks* hooks, GlobalMapperReport* report,
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
  for (int round = 0; refine && round < options.num_refinement_rounds; ++round) {
    ThrowIfStopRequested(hooks, "global mapping (bundles)");
    state.GlobalRefinement(mapper_report);
  }
  const int dropped = DropWeakFrames(ordered, options.min_frame_points, &state);
  report->num_frames_dropped += dropped;
  if (refine && dropped > 0 && rec.NumRegImages() >= 2) {
    state.GlobalRefinement(mapper_report);
  }
  report->seconds_bundles += timer.ElapsedSeconds();
  if (rec.NumRegImages() < 2) return std::nullopt;
  rec.UpdateReprojectionErrors();
  return std::move(rec);
}

}  // namespace loopsfm
