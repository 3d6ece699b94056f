#include "loopsfm/sfm/loop_closure.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "loopsfm/estimators/pose_graph.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/track_split.h"
#include "loopsfm/tracks/track_builder.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

MapperInput WithoutLoopPairs(const MapperInput& input, int min_frame_gap) {
  std::unordered_map<image_t, int> index;
  std::unordered_map<image_t, size_t> num_points2D;
  for (size_t i = 0; i < input.frames.size(); ++i) {
    index[input.frames[i].image_id] = static_cast<int>(i);
    num_points2D[input.frames[i].image_id] = input.frames[i].points2D.size();
  }
  MapperInput withheld;
  withheld.cameras = input.cameras;
  withheld.frames = input.frames;
  for (const MapperPair& pair : input.pairs) {
    if (std::abs(index.at(pair.pair.image_id1) - index.at(pair.pair.image_id2)) < min_frame_gap) {
      withheld.pairs.push_back(pair);
    }
  }
  std::vector<VerifiedPairMatches> verified;
  for (const MapperPair& pair : withheld.pairs) {
    verified.push_back({pair.pair, &pair.geometry.inlier_matches});
  }
  withheld.tracks = BuildTracks(num_points2D, verified, {}, nullptr);
  return withheld;
}

Reconstruction CloseLoopsAfterMapping(const MapperInput& input, const Reconstruction& model,
                                      const IncrementalMapperOptions& options,
                                      MapperReport* report) {
  Timer timer;
  MapperState state(input, options);
  Reconstruction& rec = state.reconstruction();
  for (const auto& [id, camera] : model.Cameras()) rec.GetCamera(id) = camera;
  std::vector<image_t> ordered;
  for (const MapperFrame& frame : input.frames) {
    if (!model.ExistsImage(frame.image_id) || !model.IsRegistered(frame.image_id)) continue;
    rec.GetImage(frame.image_id).cam_from_world = model.GetImage(frame.image_id).cam_from_world;
    rec.RegisterImage(frame.image_id);
    ordered.push_back(frame.image_id);
  }
  if (ordered.size() < 2) return model;
  state.SetGauge(ordered[0], ordered[1]);
  for (image_t id : ordered) state.TriangulateImage(id);
  const double seconds_triangulation = timer.ElapsedSeconds();
  report->seconds_triangulation += seconds_triangulation;
  const LoopClosureOptions& loop = options.loop_closure;
  bool corrected = false;
  if (loop.CloseWhileMapping()) {
    LoopCloser closer(input, loop, options.seed + 1, /*refine=*/false);
    for (image_t id : ordered) closer.AfterRegistration(state, id, report);
    corrected = closer.CloseGathered(state, report);
  }
  // Split tracks start from a refined map after the pose graph, from the map as triangulated
  // without it; their pass ends with a bundle of its own.
  if (corrected) {
    state.RefineAfterCorrection(report, loop.refine_function_tolerance);
  } else if (!loop.SplitTracks() || loop.CloseWhileMapping()) {
    state.GlobalRefinement(report);
  }
  if (loop.SplitTracks()) {
    Random split_random(options.seed + 2);
    const int tied = CloseLoopsBySplitTracks(state, loop, split_random, report);
    if (tied == 0 && !loop.CloseWhileMapping()) state.GlobalRefinement(report);
  }
  spdlog::info("loop pairs added after mapping: {} loops closed, {:.1f} s",
               report->loops_closed.size(), timer.ElapsedSeconds());
  return rec;
}

LoopCloser::LoopCloser(const MapperInput& input, const LoopClosureOptions& options,
                       uint64_t seed, bool refine)
    : input_(input), options_(options), random_(seed), refine_(refine) {
  for (size_t i = 0; i < input.frames.size(); ++i) {
    frame_index_[input.frames[i].image_id] = static_cast<int>(i);
  }
}

void LoopCloser::Save(MapperCheckpoint* checkpoint) const {
  checkpoint->loop_random_state = random_.State();
  checkpoint->loop_window.assign(window_.begin(), window_.end());
  checkpoint->loop_cooldown = cooldown_;
}

void LoopCloser::Restore(const MapperCheckpoint& checkpoint) {
  std::optional<Random> random = Random::FromState(checkpoint.loop_random_state);
  if (!random) throw InputError("the loop closer's saved random state is not one");
  random_ = *random;
  window_.assign(checkpoint.loop_window.begin(), checkpoint.loop_window.end());
  window_evidence_.clear();  // collected again when needed
  cooldown_ = checkpoint.loop_cooldown;
}

LoopCloser::Evidence LoopCloser::CollectEvidence(const MapperState& model,
                                                 image_t image_id) const {
  const Reconstruction& rec = model.reconstruction();
  const Image& image = rec.GetImage(image_id);
  const int now = frame_index_.at(image_id);
  const int old_end = now - options_.min_frame_gap;
  // Which end a point belongs to, from its observations other than this frame's:
  // +1 recent (all after old_end), -1 old (all at or before it), 0 both or none.
  auto side_of = [&](const Point3D& point) {
    bool any_old = false, any_recent = false;
    for (const TrackElement& el : point.track.elements) {
      if (el.image_id == image_id) continue;
      (frame_index_.at(el.image_id) <= old_end ? any_old : any_recent) = true;
    }
    return any_old == any_recent ? 0 : (any_recent ? 1 : -1);
  };
  Evidence evidence;
  evidence.image_id = image_id;
  if (old_end < 0) return evidence;
  for (point2D_t idx = 0; idx < image.points2D.size(); ++idx) {
    const point3D_t seen_id = image.points2D[idx].point3D_id;
    if (seen_id == kInvalidPoint3DId) continue;
    const int track = model.TrackOf(image_id, idx);
    if (track < 0) continue;
    const std::vector<point3D_t> points = model.PointsOfTrack(track);
    if (points.size() < 2) continue;
    const int seen_side = side_of(rec.GetPoint3D(seen_id));
    if (seen_side == 0) continue;
    for (point3D_t other_id : points) {
      if (other_id == seen_id || side_of(rec.GetPoint3D(other_id)) != -seen_side) continue;
      const point3D_t recent_id = seen_side > 0 ? seen_id : other_id;
      const point3D_t old_id = seen_side > 0 ? other_id : seen_id;
      const Point3D& recent = rec.GetPoint3D(recent_id);
      const Point3D& old = rec.GetPoint3D(old_id);
      PointCorrespondence c;
      c.src_xyz = recent.xyz;
      c.dst_xyz = old.xyz;
      c.src_obs = FirstObservation(rec, recent);
      c.dst_obs = FirstObservation(rec, old);
      evidence.correspondences.push_back(c);
      evidence.recent_points.push_back(recent_id);
      evidence.old_points.push_back(old_id);
      break;
    }
  }
  return evidence;
}

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

bool LoopCloser::AfterRegistration(MapperState& model, image_t image_id, MapperReport* report) {
  Timer timer;
  const bool closed = DetectAndClose(model, image_id, report);
  report->seconds_loop_detection += timer.ElapsedSeconds();
  return closed;
}

bool LoopCloser::DetectAndClose(MapperState& model, image_t image_id, MapperReport* report) {
  if (cooldown_ > 0) --cooldown_;
  Evidence evidence = CollectEvidence(model, image_id);
  if (static_cast<int>(evidence.correspondences.size()) < options_.min_frame_correspondences) {
    ClearWindow();  // the registrations with evidence must be consecutive
    return false;
  }
  window_.push_back(image_id);
  if (!refine_) window_evidence_.push_back(evidence);
  while (static_cast<int>(window_.size()) > options_.num_consistent) window_.pop_front();
  while (window_evidence_.size() > window_.size()) window_evidence_.pop_front();
  if (static_cast<int>(window_.size()) < options_.num_consistent || cooldown_ > 0) return false;

  // While mapping, points may have moved or gone since the older registrations of the
  // window: collect theirs again. After mapping the model stays as it was, and each
  // frame's evidence is collected once instead of num_consistent times.
  const bool kept = window_evidence_.size() == window_.size();
  std::vector<Evidence> current;
  for (size_t f = 0; f + 1 < window_.size(); ++f) {
    current.push_back(kept ? window_evidence_[f] : CollectEvidence(model, window_[f]));
  }
  current.push_back(std::move(evidence));
  std::vector<PointCorrespondence> all;
  std::vector<size_t> frame_of;
  for (size_t f = 0; f < current.size(); ++f) {
    for (const PointCorrespondence& c : current[f].correspondences) {
      all.push_back(c);
      frame_of.push_back(f);
    }
  }
  const PointAlignment alignment =
      AlignPointSets(all, options_.max_reproj_error_px, 2000, random_);
  if (!alignment.success || alignment.num_inliers < options_.min_num_inliers ||
      alignment.num_inliers < options_.min_inlier_ratio * all.size()) {
    return false;
  }
  std::vector<int> frame_inliers(current.size(), 0);
  for (size_t k = 0; k < all.size(); ++k) frame_inliers[frame_of[k]] += alignment.inlier_mask[k];
  if (*std::min_element(frame_inliers.begin(), frame_inliers.end()) < options_.min_frame_inliers) {
    return false;
  }

  // Already closed? Where most inlier pairs agree as they are (their points failed to merge
  // only by a few pixels), there is nothing to correct.
  const std::vector<char> as_is = AlignmentInliers(all, Sim3d(), options_.max_reproj_error_px);
  int agree_as_is = 0;
  for (size_t k = 0; k < all.size(); ++k) agree_as_is += alignment.inlier_mask[k] && as_is[k];
  if (agree_as_is >= 0.5 * alignment.num_inliers) return false;

  // Plausible as drift?
  const Reconstruction& rec = model.reconstruction();
  const Sim3d& old_from_recent = alignment.dst_from_src;
  std::vector<int> old_indices;
  for (size_t k = 0; k < all.size(); ++k) {
    if (alignment.inlier_mask[k]) old_indices.push_back(frame_index_.at(all[k].dst_obs.image->image_id));
  }
  std::nth_element(old_indices.begin(), old_indices.begin() + old_indices.size() / 2,
                   old_indices.end());
  const int old_index = old_indices[old_indices.size() / 2];
  const DriftCorrection correction = MeasureCorrection(
      rec, input_, old_from_recent, image_id, old_index, frame_index_.at(image_id), options_);
  const double translation = correction.translation;
  const double fraction = correction.fraction_of_path;
  const double scale = correction.scale;
  if (!correction.plausible) {
    ++report->num_loops_refused;
    spdlog::info("loop: refused {} -> {} ({} inliers): a correction of {:.3g} ({:.1f} % of the "
                 "path between them), scale {:.3f}, is too large for drift",
                 rec.GetImage(image_id).name, input_.frames[old_index].name, alignment.num_inliers,
                 translation, 100.0 * fraction, scale);
    ClearWindow();
    cooldown_ = options_.num_consistent;
    return false;
  }

  const Camera& camera = rec.GetCamera(rec.GetImage(image_id).camera_id);
  const bool focal_fixed =
      camera.has_prior_focal_length && !model.options().refine_known.focal_length;
  if (focal_fixed && correction.SuggestsWrongIntrinsics() && !warned_intrinsics_) {
    warned_intrinsics_ = true;
    spdlog::warn("loop: the correction turns the recent end by {:.1f} deg, {:.1f} % of the "
                 "{:.0f} deg the camera turned between the two ends. Intrinsics that are off "
                 "do this (a focal length e % off can measure turns up to about e % wrong), and "
                 "closing loops cannot undo it: the given intrinsics are held fixed. If they "
                 "are not exact, run again with --refine focal (or without --intrinsics)",
                 correction.rotation_deg, 100.0 * correction.rotation_deg / correction.turning_deg,
                 correction.turning_deg);
  }

  // Loop edges, one per registration of the window: between the old frame that sees most
  // of its inlier old points and the recent frame that sees most of their recent partners.
  std::vector<std::pair<image_t, image_t>> loop_edges;
  std::vector<int> edge_pairs;  // inlier point pairs behind each edge
  auto most_votes = [&](const std::map<image_t, int>& votes) {
    return std::max_element(votes.begin(), votes.end(), [](const auto& a, const auto& b) {
             return a.second < b.second;
           })->first;
  };
  std::vector<PointPair> inlier_pairs;
  for (size_t f = 0; f < current.size(); ++f) {
    std::map<image_t, int> old_votes, recent_votes;
    for (size_t k = 0, c = 0; k < all.size(); ++k) {
      if (frame_of[k] != f) continue;
      const size_t here = c++;
      if (!alignment.inlier_mask[k]) continue;
      inlier_pairs.push_back({current[f].old_points[here], current[f].recent_points[here]});
      for (const TrackElement& el : rec.GetPoint3D(current[f].old_points[here]).track.elements) {
        ++old_votes[el.image_id];
      }
      for (const TrackElement& el : rec.GetPoint3D(current[f].recent_points[here]).track.elements) {
        ++recent_votes[el.image_id];
      }
    }
    if (old_votes.empty() || recent_votes.empty()) continue;
    const image_t old_frame = most_votes(old_votes), recent_frame = most_votes(recent_votes);
    const auto edge = std::find(loop_edges.begin(), loop_edges.end(),
                                std::make_pair(old_frame, recent_frame));
    if (edge == loop_edges.end()) {
      loop_edges.push_back({old_frame, recent_frame});
      edge_pairs.push_back(frame_inliers[f]);
    } else {
      edge_pairs[edge - loop_edges.begin()] += frame_inliers[f];
    }
  }

  std::vector<LoopEdge> edges;
  auto world_from_cam = [&](image_t id) {
    return Sim3d::FromRigid(rec.GetImage(id).cam_from_world.Inverse());
  };
  for (const auto& [old_id, recent_id] : loop_edges) {
    edges.push_back({old_id, recent_id,
                     world_from_cam(old_id).Inverse() * old_from_recent * world_from_cam(recent_id)});
  }

  ClosedLoop loop;
  loop.recent_frame = rec.GetImage(image_id).name;
  loop.old_frame = input_.frames[old_index].name;
  loop.num_correspondences = static_cast<int>(all.size());
  loop.num_inliers = alignment.num_inliers;
  loop.correction_translation = translation;
  loop.correction_fraction_of_path = fraction;
  loop.correction_rotation_deg = correction.rotation_deg;
  loop.correction_scale = scale;
  loop.num_points_before = static_cast<long long>(rec.NumPoints3D());
  loop.num_points_after = loop.num_points_before;
  bool closed = false;
  if (refine_) {
    Timer timer;
    closed = Close(model, edges, options_.loop_edge_weight, inlier_pairs, report);
    loop.num_points_after = static_cast<long long>(model.reconstruction().NumPoints3D());
    loop.seconds = timer.ElapsedSeconds();
    report->seconds_loop_closing += loop.seconds;
    report->seconds_loop_detection -= loop.seconds;  // counted once, as closing
  } else {
    gathered_.insert(gathered_.end(), edges.begin(), edges.end());
    gathered_loops_.push_back(report->loops_closed.size());
  }
  const std::string outcome =
      refine_ ? fmt::format("points {} -> {}, {:.1f} s", loop.num_points_before,
                            loop.num_points_after, loop.seconds)
              : std::string("corrected with the others at the end");
  spdlog::info("loop: {} {} -> {} ({} of {} point pairs agree): recent end {} by {:.3g} ({:.2f} % "
               "of the path between), {:.2f} deg, scale {:.4f}; {}",
               refine_ ? "closed" : "found", loop.recent_frame, loop.old_frame, loop.num_inliers,
               loop.num_correspondences, refine_ ? "moved" : "to move",
               loop.correction_translation, 100.0 * loop.correction_fraction_of_path,
               loop.correction_rotation_deg, loop.correction_scale, outcome);
  report->loops_closed.push_back(std::move(loop));
  for (size_t e = 0; e < loop_edges.size(); ++e) {
    report->loop_links.push_back({"posegraph", rec.GetImage(loop_edges[e].first).name,
                                  rec.GetImage(loop_edges[e].second).name, edge_pairs[e]});
  }
  ClearWindow();
  // While mapping, each closing ends with a global refinement: wait for more of the loop.
  // After mapping, every window of the overlap adds its edges to the one correction.
  cooldown_ = refine_ ? options_.min_frame_gap / 2 : options_.num_consistent;
  return closed;
}

bool LoopCloser::CloseGathered(MapperState& model, MapperReport* report) {
  if (gathered_.empty()) return false;
  Timer timer;
  const long long before = static_cast<long long>(model.reconstruction().NumPoints3D());
  // Each loop's edges were measured on its own stretch of the overlap, and no two agree
  // exactly (drift is no rigid motion); at full weight each, they would pull the old end out
  // of shape between them. Together they weigh as much as one loop's.
  const double weight = options_.loop_edge_weight / static_cast<double>(gathered_loops_.size());
  const bool closed = Close(model, gathered_, weight, {}, report);
  const long long after = static_cast<long long>(model.reconstruction().NumPoints3D());
  for (size_t k : gathered_loops_) report->loops_closed[k].num_points_after = after;
  const double seconds = timer.ElapsedSeconds();
  report->seconds_loop_closing += seconds;
  spdlog::info("loop: {} loops corrected together ({} edges): points {} -> {}, {:.1f} s",
               gathered_loops_.size(), gathered_.size(), before, after, seconds);
  gathered_.clear();
  gathered_loops_.clear();
  return closed;
}

namespace {

// Diagnostic: the consecutive step that grew most against its length before the
// correction, relative to the median step's growth (a correction should spread along the
// path, not bend it in one place).
std::string StretchedStep(const Reconstruction& rec, const std::vector<image_t>& ordered,
                          const std::map<image_t, Sim3d>& before) {
  std::vector<std::pair<double, size_t>> growth;  // (now / before, index of the step's start)
  for (size_t i = 0; i + 1 < ordered.size(); ++i) {
    const image_t a = ordered[i], b = ordered[i + 1];
    const double was = (before.at(b).translation - before.at(a).translation).norm();
    const double now =
        (rec.GetImage(b).ProjectionCenter() - rec.GetImage(a).ProjectionCenter()).norm();
    if (was > 0.0) growth.push_back({now / was, i});
  }
  if (growth.empty()) return "no steps";
  std::vector<std::pair<double, size_t>> sorted = growth;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2].first;
  const auto [largest, at] = *std::max_element(growth.begin(), growth.end());
  return fmt::format("largest step {} -> {}: {:.2f}x its length before, median step {:.2f}x",
                     rec.GetImage(ordered[at]).name, rec.GetImage(ordered[at + 1]).name, largest,
                     median);
}

}  // namespace

bool LoopCloser::Close(MapperState& model, const std::vector<LoopEdge>& loop_edges,
                       double loop_weight, const std::vector<PointPair>& fuse,
                       MapperReport* report) {
  Reconstruction& rec = model.reconstruction();
  KeepPathBeforeLoopClosing(input_, rec, report);
  PoseGraph graph;
  std::vector<image_t> ordered;  // registered frames in capture order
  for (const MapperFrame& frame : input_.frames) {
    const Image& image = rec.GetImage(frame.image_id);
    if (!image.registered) continue;
    graph.AddNode(frame.image_id, Sim3d::FromRigid(image.cam_from_world.Inverse()));
    ordered.push_back(frame.image_id);
  }
  auto add_measured_edge = [&](image_t a, image_t b, double weight) {
    graph.AddEdge({.node1 = a, .node2 = b, .measured = graph.RelativeFromNodes(a, b),
                   .rotation_weight = weight, .translation_weight = weight,
                   .scale_weight = weight});
  };
  // Co-visible pairs (sharing points in the map) keep the path's shape. Consecutive frames
  // keep it connected, weakly where they share no points: a registration that jumped onto
  // the old map must not hold the drifted end in place.
  std::map<std::pair<image_t, image_t>, int> shared_points;
  for (const MapperPair& pair : input_.pairs) {
    const image_t a = pair.pair.image_id1, b = pair.pair.image_id2;
    if (!graph.HasNode(a) || !graph.HasNode(b)) continue;
    const Image& image_a = rec.GetImage(a);
    const Image& image_b = rec.GetImage(b);
    int shared = 0;
    for (const FeatureMatch& m : pair.geometry.inlier_matches) {
      const point3D_t id = image_a.points2D[m.point2D_idx1].point3D_id;
      shared += id != kInvalidPoint3DId && id == image_b.points2D[m.point2D_idx2].point3D_id;
    }
    shared_points[{std::min(a, b), std::max(a, b)}] = shared;
    if (shared >= options_.covisibility_min_points) add_measured_edge(a, b, 1.0);
  }
  for (size_t i = 0; i + 1 < ordered.size(); ++i) {
    const image_t a = ordered[i], b = ordered[i + 1];
    const auto it = shared_points.find({std::min(a, b), std::max(a, b)});
    if (it != shared_points.end() && it->second >= options_.covisibility_min_points) continue;
    add_measured_edge(a, b, 0.1);
  }
  const double w = loop_weight;
  for (const LoopEdge& edge : loop_edges) {
    graph.AddEdge({.node1 = edge.old_id, .node2 = edge.recent_id, .measured = edge.measured,
                   .rotation_weight = w, .translation_weight = w, .scale_weight = w});
  }
  const image_t gauge = model.GaugeFirst() != kInvalidImageId && graph.HasNode(model.GaugeFirst())
                            ? model.GaugeFirst()
                            : ordered.front();
  graph.SetConstant(gauge);
  const std::map<image_t, Sim3d> before = graph.Nodes();
  PoseGraphOptions pg_options;
  pg_options.num_threads = model.options().num_threads;
  if (!graph.Optimize(pg_options)) {
    spdlog::warn("loop: pose graph failed ({}); the model is left as it was",
                 graph.report().termination);
    return false;
  }

  // Points move with the observing frame in the middle of their track (capture order).
  for (auto& [id, point] : rec.Points3D()) {
    std::vector<std::pair<int, image_t>> observers;
    for (const TrackElement& el : point.track.elements) {
      observers.push_back({frame_index_.at(el.image_id), el.image_id});
    }
    std::nth_element(observers.begin(), observers.begin() + observers.size() / 2, observers.end());
    const image_t ref = observers[observers.size() / 2].second;
    point.xyz = graph.Node(ref) * (before.at(ref).Inverse() * point.xyz);
  }
  for (const auto& [id, node] : graph.Nodes()) {
    rec.GetImage(id).cam_from_world = node.ToRigid().Inverse();
  }
  const PoseGraphReport& solved = graph.report();
  spdlog::debug("loop: pose graph {} nodes, {} edges, {} iterations, {:.2f} s; {}",
                solved.num_nodes, solved.num_edges, solved.num_iterations, solved.time_s,
                StretchedStep(rec, ordered, before));
  // The loop's inlier pairs become one point each (ORB-SLAM's loop fusion): the pose graph
  // only approximates the correction, so few of them would agree to the pixel yet and merge
  // by themselves, and without points seen from both ends nothing in the refining bundle
  // holds the ends together; it relaxed a large correction back towards the drift (drift2,
  // focal -5 %: the same loop was closed 13 times). Observations a fused point cannot fit
  // are dropped after the bundle.
  size_t fused = 0;
  for (const PointPair& pair : fuse) {
    if (!rec.ExistsPoint3D(pair.old_id) || !rec.ExistsPoint3D(pair.recent_id)) continue;
    fused += model.FusePoints(pair.old_id, pair.recent_id) != kInvalidPoint3DId;
  }
  Timer timer;
  model.RetriangulateAll();
  spdlog::debug("loop: {} point pairs fused, re-triangulation {:.2f} s, {} points", fused,
                timer.ElapsedSeconds(), rec.NumPoints3D());
  if (refine_) {
    model.RefineAfterCorrection(report);
    spdlog::debug("loop: refined; {}", StretchedStep(rec, ordered, before));
  }
  return true;
}

}  // namespace loopsfm
