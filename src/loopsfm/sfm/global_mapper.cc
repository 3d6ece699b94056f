#include "loopsfm/sfm/global_mapper.h"

#include <algorithm>
#include <map>
#include <optional>
#include <unordered_map>
#include <utility>

#include "loopsfm/estimators/bearing_rays.h"
#include "loopsfm/math/graph.h"
#include "loopsfm/sfm/global_structure.h"
#include "loopsfm/sfm/global_view_graph.h"
#include "loopsfm/sfm/incremental_mapper.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

namespace {

using Rotations = std::map<image_t, Eigen::Quaterniond>;

// The direction from camera 1's centre to camera 2's in the world: cam2_from_cam1 = (R, t)
// puts camera 1's centre at t in camera 2, so c1 - c2 = R_2^T t.
Eigen::Vector3d CentreDirection(const PairPose& pose, const Eigen::Quaterniond& cam2_from_world) {
  return -(cam2_from_world.conjugate() * pose.cam2_from_cam1.translation).normalized();
}

// Stage 1: the edges of the view graph that cleaning keeps, one list per connected component
// of at least min_model_size frames, largest first, at most max_num_models of them; with
// split_at_cuts, no edge across a cut.
std::vector<std::vector<RelativeRotation>> CleanedComponents(
    const MapperInput& input, const FrameLookup& lookup, const std::vector<PairPose>& pair_poses,
    const GlobalMapperOptions& options, const IncrementalMapperOptions& mapper_options,
    GlobalMapperReport* report) {
  Timer timer;
  const std::vector<int> run = RunsBetweenCuts(input);
  report->num_cuts = run.empty() ? 0 : run.back();
  report->num_pairs_across_cuts = 0;
  std::vector<RelativeRotation> edges;
  for (const PairPose& pose : pair_poses) {
    if (options.split_at_cuts && run[lookup.CaptureIndex(pose.image_id1)] !=
                                     run[lookup.CaptureIndex(pose.image_id2)]) {
      ++report->num_pairs_across_cuts;
      continue;
    }
    edges.push_back({pose.image_id1, pose.image_id2, pose.cam2_from_cam1.rotation, pose.weight});
  }
  report->num_view_graph_edges = static_cast<int>(edges.size());
  const ViewGraphCleaningResult cleaned = CleanViewGraph(edges, options.view_graph);
  report->view_graph = cleaned.report;

  std::map<image_t, int> node_of;
  for (const int e : cleaned.kept_edges) {
    node_of.emplace(edges[e].node1, 0);
    node_of.emplace(edges[e].node2, 0);
  }
  int num_nodes = 0;
  for (auto& [id, node] : node_of) node = num_nodes++;
  std::vector<std::pair<int, int>> links;
  for (const int e : cleaned.kept_edges) {
    links.push_back({node_of.at(edges[e].node1), node_of.at(edges[e].node2)});
  }
  const GraphComponents components = ConnectedComponents(num_nodes, links);  // largest first
  std::vector<std::vector<RelativeRotation>> parts(components.NumComponents());
  for (size_t k = 0; k < links.size(); ++k) {
    parts[components.label[links[k].first]].push_back(edges[cleaned.kept_edges[k]]);
  }
  std::vector<std::vector<RelativeRotation>> mapped;
  for (int c = 0; c < components.NumComponents(); ++c) {
    if (components.sizes[c] >= mapper_options.min_model_size &&
        static_cast<int>(mapped.size()) < mapper_options.max_num_models) {
      mapped.push_back(std::move(parts[c]));
    } else {
      report->num_frames_in_other_components += components.sizes[c];
    }
  }
  report->num_components = components.NumComponents();
  report->num_components_mapped = static_cast<int>(mapped.size());
  report->seconds_view_graph = timer.ElapsedSeconds();
  spdlog::info("global mapper: view graph {} edges ({} cut{} in the video, {} pairs across left "
               "out; {} of {} planar pairs with the homography's pose), {} dropped around "
               "triangles; {} connected component{}, {} mapped ({} frames in the others)",
               edges.size(), report->num_cuts, report->num_cuts == 1 ? "" : "s",
               report->num_pairs_across_cuts, report->num_planar_poses_from_homography,
               report->num_planar_pairs, cleaned.report.num_dropped_by_triangles,
               report->num_components,
               report->num_components == 1 ? "" : "s", report->num_components_mapped,
               report->num_frames_in_other_components);
  return mapped;
}

// Stage 2: the rotations of the frames of one component. The report keeps the rotation
// averaging report of the first (largest) component only.
Rotations AverageComponent(const std::vector<RelativeRotation>& edges,
                           const GlobalMapperOptions& options, bool first,
                           GlobalMapperReport* report) {
  Timer timer;
  const RotationAveragingResult averaged = AverageRotations(edges, options.rotation_averaging);
  if (first) {
    report->rotations = averaged.report;
    report->rotations.edge_residual_deg.clear();  // per edge: not for the report
  }
  std::unordered_map<image_t, int> good_edges;
  int num_outliers = 0;
  for (size_t e = 0; e < edges.size(); ++e) {
    const double residual = averaged.report.edge_residual_deg[e];
    if (residual < 0.0) continue;
    if (residual > options.max_rotation_error_deg) {
      ++num_outliers;
      continue;
    }
    ++good_edges[edges[e].node1];
    ++good_edges[edges[e].node2];
  }
  Rotations rotations;
  int num_without_edges = 0;
  for (const auto& [id, rotation] : averaged.cam_from_world) {
    if (good_edges.count(id) > 0) {
      rotations[id] = rotation;
    } else {
      ++num_without_edges;
    }
  }
  report->num_rotation_outliers += num_outliers;
  report->num_frames_without_edges += num_without_edges;
  const double seconds = timer.ElapsedSeconds();
  report->seconds_rotations += seconds;
  spdlog::info("global mapper: rotations of {} frames, {} edges disagree by more than {:.0f} deg, "
               "{:.1f} s",
               rotations.size(), num_outliers, options.max_rotation_error_deg, seconds);
  return rotations;
}

// A start for global positioning along the video: frames in capture order one unit apart,
// each step along the direction its pair's relative pose gives (the step before's where the
// two frames have no pair with a translation), and every point where its rays from those
// centres meet.
void ChainedStart(const MapperInput& input, const Rotations& rotations,
                  const std::vector<PairPose>& pair_poses, GlobalPositioningInput* positioning) {
  std::map<std::pair<image_t, image_t>, const PairPose*> pose_of;
  for (const PairPose& pose : pair_poses) {
    if (pose.has_translation) pose_of[{pose.image_id1, pose.image_id2}] = &pose;
  }
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  Eigen::Vector3d step = Eigen::Vector3d::Zero();
  image_t previous = kInvalidImageId;
  for (const MapperFrame& frame : input.frames) {
    const auto rotation = rotations.find(frame.image_id);
    if (rotation == rotations.end()) continue;
    if (previous != kInvalidImageId) {
      if (const auto forward = pose_of.find({previous, frame.image_id}); forward != pose_of.end()) {
        step = CentreDirection(*forward->second, rotation->second);
      } else if (const auto backward = pose_of.find({frame.image_id, previous});
                 backward != pose_of.end()) {
        step = -CentreDirection(*backward->second, rotations.at(previous));
      }
      centre += step.squaredNorm() > 0.0 ? step : Eigen::Vector3d::UnitX();
    }
    positioning->initial_centres[frame.image_id] = centre;
    previous = frame.image_id;
  }
  std::map<point3D_t, std::vector<BearingRay>> rays;
  for (const BearingObservation& obs : positioning->observations) {
    const Eigen::Vector3d direction =
        (rotations.at(obs.image_id).conjugate() * obs.bearing_in_cam).normalized();
    rays[obs.point_id].push_back({positioning->initial_centres.at(obs.image_id), direction});
  }
  for (const auto& [id, point_rays] : rays) {
    if (const std::optional<Eigen::Vector3d> point = IntersectRays(point_rays)) {
      positioning->initial_points[id] = *point;
    }
  }
}

// The elements of a track in frames with a rotation, at most `max` of them spread evenly
// over the track in capture order.
std::vector<const TrackElement*> SpreadObservations(const std::vector<TrackElement>& elements,
                                                    const Rotations& rotations,
                                                    const FrameLookup& lookup, int max) {
  std::vector<const TrackElement*> in_model;
  for (const TrackElement& el : elements) {
    if (rotations.count(el.image_id) > 0) in_model.push_back(&el);
  }
  const size_t n = in_model.size(), kept = std::min(n, static_cast<size_t>(max));
  if (kept == n) return in_model;
  std::stable_sort(in_model.begin(), in_model.end(), [&](const auto* a, const auto* b) {
    return lookup.CaptureIndex(a->image_id) < lookup.CaptureIndex(b->image_id);
  });
  std::vector<const TrackElement*> spread(kept);
  for (size_t i = 0; i < kept; ++i) {
    spread[i] = in_model[(i * (n - 1) + (kept - 1) / 2) / (kept - 1)];  // rounded
  }
  return spread;
}

// Stage 3's input: the bearings of the tracks chosen (see GlobalMapperOptions), each track's
// index standing for its point.
GlobalPositioningInput PositioningInput(const MapperInput& input, const FrameLookup& lookup,
                                        const Rotations& rotations,
                                        const std::vector<PairPose>& pair_poses,
                                        const GlobalMapperOptions& options, int* num_tracks) {
  std::vector<std::pair<int, size_t>> candidates;  // (-frames in the model, track)
  for (size_t t = 0; t < input.tracks.size(); ++t) {
    int length = 0;
    for (const TrackElement& el : input.tracks[t].elements) length += rotations.count(el.image_id);
    if (length >= options.min_track_length) candidates.push_back({-length, t});
  }
  std::sort(candidates.begin(), candidates.end());
  GlobalPositioningInput positioning;
  positioning.cam_from_world_rotations = rotations;
  std::unordered_map<image_t, int> taken;
  *num_tracks = 0;
  for (const auto& [length, t] : candidates) {
    const std::vector<TrackElement>& elements = input.tracks[t].elements;
    const bool wanted = std::any_of(elements.begin(), elements.end(), [&](const TrackElement& el) {
      return rotations.count(el.image_id) > 0 && taken[el.image_id] < options.max_tracks_per_frame;
    });
    if (!wanted) continue;
    ++*num_tracks;
    for (const TrackElement* spread : SpreadObservations(elements, rotations, lookup,
                                                         options.max_observations_per_track)) {
      const TrackElement& el = *spread;
      ++taken[el.image_id];
      const Eigen::Vector2d xy =
          lookup.CameraOf(el.image_id)
              .CamFromImg(lookup.Frame(el.image_id).points2D.at(el.point2D_idx));
      positioning.observations.push_back(
          {el.image_id, static_cast<point3D_t>(t), Eigen::Vector3d(xy.x(), xy.y(), 1.0)});
    }
  }
  if (options.pair_directions) {
    for (const PairPose& pose : pair_poses) {
      const auto rotation2 = rotations.find(pose.image_id2);
      if (!pose.has_translation || rotations.count(pose.image_id1) == 0 ||
          rotation2 == rotations.end()) {
        continue;
      }
      positioning.camera_directions.push_back(
          {pose.image_id1, pose.image_id2, CentreDirection(pose, rotation2->second)});
    }
  }
  if (options.chained_start) ChainedStart(input, rotations, pair_poses, &positioning);
  return positioning;
}

// Stage 3 for one component with its frames' rotations: the poses global positioning
// gives, or nullopt where it fails. The report keeps the positioning report of the first
// (largest) component only.
std::optional<std::map<image_t, Rigid3d>> PositionComponent(
    const MapperInput& input, const FrameLookup& lookup,
    const IncrementalMapperOptions& mapper_options, const GlobalMapperOptions& options,
    const std::vector<PairPose>& pair_poses, const Rotations& rotations, bool first,
    GlobalMapperReport* report) {
  Timer timer;
  int num_tracks = 0;
  const GlobalPositioningInput positioning_input =
      PositioningInput(input, lookup, rotations, pair_poses, options, &num_tracks);
  report->num_tracks_positioned += num_tracks;
  GlobalPositioningOptions positioning_options = options.positioning;
  positioning_options.num_threads = mapper_options.num_threads;
  positioning_options.seed = mapper_options.seed;
  const GlobalPositioningResult positioned =
      SolveGlobalPositioning(positioning_input, positioning_options);
  if (first) report->positioning = positioned.report;
  const double seconds = timer.ElapsedSeconds();
  report->seconds_positioning += seconds;
  spdlog::info("global mapper: positions of {} frames and {} tracks ({} observations), {} "
               "iterations, {:.1f} s{}",
               positioned.camera_centres.size(), positioned.points.size(),
               positioned.report.num_observations, positioned.report.num_iterations, seconds,
               positioned.report.success ? "" : ": " + positioned.report.termination);
  const double off = positioned.report.LargeAngleFraction();
  if (positioned.report.success && off > options.max_off_observation_fraction) {
    ++report->num_bent_components;
    spdlog::warn("global mapper: global positioning of {} frames leaves {:.0f} % of its "
                 "observations more than {:.0f} deg off: many wrong matches, such as repeated "
                 "structure (identical buildings) gives; the path is likely bent, and the "
                 "bundles will not straighten it",
                 rotations.size(), 100.0 * off,
                 positioning_options.max_angle_error_deg);
  }
  if (!positioned.report.success || positioned.camera_centres.size() < 2) {
    spdlog::warn("global mapper: global positioning of {} frames failed ({}); no model of them",
                 rotations.size(), positioned.report.termination);
    return std::nullopt;
  }
  return CamFromWorldFromCentres(rotations, positioned.camera_centres);
}

// One run of the global mapper: the stages in order, for each component from where its
// checkpoint left it, with the progress handed to checkpointing.save after each.
class GlobalMapping {
 public:
  GlobalMapping(const MapperInput& input, const IncrementalMapperOptions& mapper_options,
                const GlobalMapperOptions& options, const GlobalMapperCheckpointing& checkpointing,
                const RunHooks* hooks, GlobalMapperReport* report, MapperReport* mapper_report)
      : input_(input),
        lookup_(input),
        mapper_options_(mapper_options),
        options_(options),
        checkpointing_(checkpointing),
        hooks_(hooks),
        report_(report),
        mapper_report_(mapper_report) {}

  std::vector<Reconstruction> Run() {
    if (checkpointing_.resume) {
      Resume(*checkpointing_.resume);
    } else {
      report_->num_frames = static_cast<int>(input_.frames.size());
      for (std::vector<RelativeRotation>& edges :
           CleanedComponents(input_, lookup_, VerifiedPairPoses(), options_, mapper_options_,
                             report_)) {
        progress_.components.push_back({.edges = std::move(edges)});
      }
      Save();
    }
    ThrowIfStopRequested(hooks_, "global mapping (view graph)");
    std::vector<Reconstruction> models;
    for (size_t c = 0; c < progress_.components.size(); ++c) {
      if (options_.stop_when_bent && report_->num_bent_components > 0) return {};
      std::optional<Reconstruction> model = MapComponent(c);
      if (model) models.push_back(std::move(*model));
    }
    return models;
  }

 private:
  // The report goes on from the checkpoint's, but its stage times are this run's (the
  // summary gives them as the time each stage took now).
  void Resume(const GlobalMapperCheckpoint& checkpoint) {
    progress_ = checkpoint;
    *report_ = checkpoint.report;
    report_->seconds_view_graph = report_->seconds_rotations = report_->seconds_positioning =
        report_->seconds_triangulation = report_->seconds_bundles = 0.0;
    *mapper_report_ = checkpoint.mapper_report;
    int done = 0;
    for (const GlobalMapperCheckpoint::Component& component : progress_.components) {
      done += component.done ? 1 : 0;
    }
    spdlog::info("global mapper: going on from its checkpoint, {} of {} component{} mapped",
                 done, progress_.components.size(),
                 progress_.components.size() == 1 ? "" : "s");
  }

  void Save() {
    if (!checkpointing_.save) return;
    progress_.report = *report_;
    progress_.mapper_report = *mapper_report_;
    checkpointing_.save(progress_);
  }

  // Every verified pair's relative pose, found once (the view graph and positioning use it).
  const std::vector<PairPose>& VerifiedPairPoses() {
    if (!pair_poses_) pair_poses_ = PairPoses(input_, lookup_, options_, report_);
    return *pair_poses_;
  }

  // Stages 2 to 4 of component c, from where its checkpoint left it; its model, if any.
  std::optional<Reconstruction> MapComponent(size_t c) {
    GlobalMapperCheckpoint::Component& component = progress_.components[c];
    if (component.done) return RestoredModel(component);
    const bool first = c == 0;
    if (!component.rotations) {
      component.rotations = AverageComponent(component.edges, options_, first, report_);
      component.done = component.rotations->size() < 2;
      Save();
      ThrowIfStopRequested(hooks_, "global mapping (rotations)");
      if (component.done) return std::nullopt;
    }
    if (!component.positioned) {
      std::optional<std::map<image_t, Rigid3d>> poses =
          PositionComponent(input_, lookup_, mapper_options_, options_, VerifiedPairPoses(),
                            *component.rotations, first, report_);
      component.done = !poses || (options_.stop_when_bent && report_->num_bent_components > 0);
      component.positioned = std::move(poses);
      Save();
      ThrowIfStopRequested(hooks_, "global mapping (positions)");
      if (component.done) return std::nullopt;
    }
    if (!component.loose) {
      component.loose = LooseBundles(input_, mapper_options_, options_, *component.positioned,
                                     hooks_, report_, mapper_report_);
      component.done = !component.loose;
      Save();
      if (component.done) return std::nullopt;
    }
    const bool joined_later = report_->num_pairs_across_cuts > 0;
    std::optional<Reconstruction> model =
        RefinedModel(input_, mapper_options_, options_, *component.loose, !joined_later, hooks_,
                     report_, mapper_report_);
    component.done = true;
    if (model) component.model = model->SaveMapped();
    Save();
    return model;
  }

  std::optional<Reconstruction> RestoredModel(
      const GlobalMapperCheckpoint::Component& component) const {
    if (!component.model) return std::nullopt;
    Reconstruction model = EmptyReconstruction(input_);
    model.RestoreMapped(*component.model);
    return model;
  }

  const MapperInput& input_;
  const FrameLookup lookup_;
  const IncrementalMapperOptions& mapper_options_;
  const GlobalMapperOptions& options_;
  const GlobalMapperCheckpointing& checkpointing_;
  const RunHooks* hooks_;
  GlobalMapperReport* report_;
  MapperReport* mapper_report_;
  GlobalMapperCheckpoint progress_;
  std::optional<std::vector<PairPose>> pair_poses_;
};

// The models mapped between the video's cuts, joined by the incremental mapper: it merges
// them where their points agree and registers the frames no model has (without loop
// closing: the loop pairs are in the view graphs already).
std::vector<Reconstruction> JoinAcrossCuts(const MapperInput& input,
                                           const IncrementalMapperOptions& mapper_options,
                                           const std::vector<Reconstruction>& models,
                                           GlobalMapperReport* report,
                                           MapperReport* mapper_report) {
  Timer timer;
  IncrementalMapperOptions join_options = mapper_options;
  join_options.loop_closure.method = LoopClosingMethod::kNone;
  std::vector<Reconstruction> joined =
      ExtendIncrementalModels(input, join_options, models, mapper_report);
  report->seconds_joining = timer.ElapsedSeconds();
  spdlog::info("global mapper: the {} model{} mapped between {} cut{} joined into {} by their "
               "shared points, {:.1f} s",
               models.size(), models.size() == 1 ? "" : "s", report->num_cuts,
               report->num_cuts == 1 ? "" : "s", joined.size(), report->seconds_joining);
  return joined;
}

}  // namespace

std::vector<Reconstruction> RunGlobalMapper(const MapperInput& input,
                                            const IncrementalMapperOptions& mapper_options,
                                            const GlobalMapperOptions& options,
                                            GlobalMapperReport* report,
                                            MapperReport* mapper_report, const RunHooks* hooks,
                                            const GlobalMapperCheckpointing& checkpointing) {
  mapper_options.Check();
  options.Check();
  GlobalMapperReport local_report;
  MapperReport local_mapper_report;
  if (!report) report = &local_report;
  if (!mapper_report) mapper_report = &local_mapper_report;
  *report = {};
  std::vector<Reconstruction> models =
      GlobalMapping(input, mapper_options, options, checkpointing, hooks, report, mapper_report)
          .Run();
  if (report->num_pairs_across_cuts > 0 && !models.empty()) {
    models = JoinAcrossCuts(input, mapper_options, models, report, mapper_report);
  }
  if (options.stop_when_bent && report->num_bent_components > 0) {
    spdlog::info("global mapper: stopped at a component likely bent; no model");
    return {};
  }
  if (models.empty()) {
    spdlog::warn("global mapper: no part of the view graph could be mapped; no model");
    return models;
  }
  // Frames dropped from a model can make a later one larger.
  std::stable_sort(models.begin(), models.end(), [](const auto& a, const auto& b) {
    return a.NumRegImages() > b.NumRegImages();
  });
  report->num_registered = 0;
  for (const Reconstruction& model : models) {
    report->num_registered += static_cast<int>(model.NumRegImages());
  }
  mapper_report->num_registered = report->num_registered;
  mapper_report->num_models = static_cast<int>(models.size());
  CheckPathJumps(input, models, options, report);
  spdlog::info("global mapper: {} of {} frames in {} model{} ({} dropped for too few points), "
               "triangulation {:.1f} s, bundles {:.1f} s",
               report->num_registered, report->num_frames, models.size(),
               models.size() == 1 ? "" : "s", report->num_frames_dropped,
               report->seconds_triangulation, report->seconds_bundles);
  return models;
}

}  // namespace loopsfm
