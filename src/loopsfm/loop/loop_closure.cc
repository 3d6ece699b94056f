#include "loopsfm/loop/loop_closure.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "loopsfm/estimators/pose_graph.h"
#include "loopsfm/loop/drift_correction.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

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

bool LoopCloser::AfterRegistration(MapperState& model, image_t image_id, MapperReport* report) {
  Timer timer;
  const bool closed = DetectAndClose(model, image_id, report);
  report->seconds_loop_detection += timer.ElapsedSeconds();
  return closed;
}

bool LoopCloser::DetectAndClose(MapperState& model, image_t image_id, MapperReport* report) {
  if (cooldown_ > 0) --cooldown_;
  const std::vector<Evidence> window = UpdateWindow(model, image_id);
  if (window.empty()) return false;
  std::optional<Hypothesis> loop = Align(window);
  if (!loop) return false;
  const Reconstruction& rec = model.reconstruction();
  const int old_index = loop->MedianOldIndex(frame_index_);
  const DriftCorrection correction =
      MeasureCorrection(rec, input_, loop->alignment.dst_from_src, image_id, old_index,
                        frame_index_.at(image_id), options_);
  if (!correction.plausible) {
    ++report->num_loops_refused;
    spdlog::info("loop: refused {} -> {} ({} inliers): a correction of {:.3g} ({:.1f} % of the "
                 "path between them), scale {:.3f}, is too large for drift",
                 rec.GetImage(image_id).name, input_.frames[old_index].name,
                 loop->alignment.num_inliers, correction.translation,
                 100.0 * correction.fraction_of_path, correction.scale);
    ClearWindow();
    cooldown_ = options_.num_consistent;
    return false;
  }
  WarnIfIntrinsicsLookWrong(model, image_id, correction);
  const LoopEdges edges = EdgesOf(rec, window, *loop);
  ClosedLoop closed_loop;
  closed_loop.recent_frame = rec.GetImage(image_id).name;
  closed_loop.old_frame = input_.frames[old_index].name;
  closed_loop.num_correspondences = static_cast<int>(loop->all.size());
  closed_loop.num_inliers = loop->alignment.num_inliers;
  closed_loop.correction_translation = correction.translation;
  closed_loop.correction_fraction_of_path = correction.fraction_of_path;
  closed_loop.correction_rotation_deg = correction.rotation_deg;
  closed_loop.correction_scale = correction.scale;
  const bool closed = CorrectOrGather(model, edges, std::move(closed_loop), report);
  ClearWindow();
  // While mapping, each closing ends with a global refinement: wait for more of the loop.
  // After mapping, every window of the overlap adds its edges to the one correction.
  cooldown_ = refine_ ? options_.min_frame_gap / 2 : options_.num_consistent;
  return closed;
}

std::vector<LoopCloser::Evidence> LoopCloser::UpdateWindow(const MapperState& model,
                                                           image_t image_id) {
  Evidence evidence = CollectEvidence(model, image_id);
  if (static_cast<int>(evidence.correspondences.size()) < options_.min_frame_correspondences) {
    ClearWindow();  // the registrations with evidence must be consecutive
    return {};
  }
  window_.push_back(image_id);
  if (!refine_) window_evidence_.push_back(evidence);
  while (static_cast<int>(window_.size()) > options_.num_consistent) window_.pop_front();
  while (window_evidence_.size() > window_.size()) window_evidence_.pop_front();
  if (static_cast<int>(window_.size()) < options_.num_consistent || cooldown_ > 0) return {};

  // While mapping, points may have moved or gone since the older registrations of the
  // window: collect theirs again. After mapping the model stays as it was, and each
  // frame's evidence is collected once instead of num_consistent times.
  const bool kept = window_evidence_.size() == window_.size();
  std::vector<Evidence> window;
  for (size_t f = 0; f + 1 < window_.size(); ++f) {
    window.push_back(kept ? window_evidence_[f] : CollectEvidence(model, window_[f]));
  }
  window.push_back(std::move(evidence));
  return window;
}

std::optional<LoopCloser::Hypothesis> LoopCloser::Align(const std::vector<Evidence>& window) {
  Hypothesis loop;
  for (size_t f = 0; f < window.size(); ++f) {
    for (const PointCorrespondence& c : window[f].correspondences) {
      loop.all.push_back(c);
      loop.frame_of.push_back(f);
    }
  }
  loop.alignment = AlignPointSets(loop.all, options_.max_reproj_error_px, 2000, random_);
  if (!loop.alignment.success || loop.alignment.num_inliers < options_.min_num_inliers ||
      loop.alignment.num_inliers < options_.min_inlier_ratio * loop.all.size()) {
    return std::nullopt;
  }
  loop.frame_inliers.assign(window.size(), 0);
  for (size_t k = 0; k < loop.all.size(); ++k) {
    loop.frame_inliers[loop.frame_of[k]] += loop.alignment.inlier_mask[k];
  }
  if (*std::min_element(loop.frame_inliers.begin(), loop.frame_inliers.end()) <
      options_.min_frame_inliers) {
    return std::nullopt;
  }
  // Already closed? Where most inlier pairs agree as they are (their points failed to merge
  // only by a few pixels), there is nothing to correct.
  const std::vector<char> as_is =
      AlignmentInliers(loop.all, Sim3d(), options_.max_reproj_error_px);
  int agree_as_is = 0;
  for (size_t k = 0; k < loop.all.size(); ++k) {
    agree_as_is += loop.alignment.inlier_mask[k] && as_is[k];
  }
  if (agree_as_is >= 0.5 * loop.alignment.num_inliers) return std::nullopt;
  return loop;
}

int LoopCloser::Hypothesis::MedianOldIndex(
    const std::unordered_map<image_t, int>& frame_index) const {
  std::vector<int> old_indices;
  for (size_t k = 0; k < all.size(); ++k) {
    if (alignment.inlier_mask[k]) old_indices.push_back(frame_index.at(all[k].dst_obs.image->image_id));
  }
  std::nth_element(old_indices.begin(), old_indices.begin() + old_indices.size() / 2,
                   old_indices.end());
  return old_indices[old_indices.size() / 2];
}

void LoopCloser::WarnIfIntrinsicsLookWrong(const MapperState& model, image_t image_id,
                                           const DriftCorrection& correction) {
  const Reconstruction& rec = model.reconstruction();
  const Camera& camera = rec.GetCamera(rec.GetImage(image_id).camera_id);
  const bool focal_fixed =
      camera.has_prior_focal_length && !model.options().refine_known.focal_length;
  if (!focal_fixed || !correction.SuggestsWrongIntrinsics() || warned_intrinsics_) return;
  warned_intrinsics_ = true;
  spdlog::warn("loop: the correction turns the recent end by {:.1f} deg, {:.1f} % of the "
               "{:.0f} deg the camera turned between the two ends. Intrinsics that are off "
               "do this (a focal length e % off can measure turns up to about e % wrong), and "
               "closing loops cannot undo it: the given intrinsics are held fixed. If they "
               "are not exact, run again with --refine focal (or without --intrinsics)",
               correction.rotation_deg, 100.0 * correction.rotation_deg / correction.turning_deg,
               correction.turning_deg);
}

LoopCloser::LoopEdges LoopCloser::EdgesOf(const Reconstruction& rec,
                                          const std::vector<Evidence>& window,
                                          const Hypothesis& loop) const {
  // One edge per registration of the window: between the old frame that sees most of its
  // inlier old points and the recent frame that sees most of their recent partners.
  std::vector<std::pair<image_t, image_t>> ends;
  LoopEdges edges;
  auto most_votes = [&](const std::map<image_t, int>& votes) {
    return std::max_element(votes.begin(), votes.end(), [](const auto& a, const auto& b) {
             return a.second < b.second;
           })->first;
  };
  for (size_t f = 0; f < window.size(); ++f) {
    std::map<image_t, int> old_votes, recent_votes;
    for (size_t k = 0, c = 0; k < loop.all.size(); ++k) {
      if (loop.frame_of[k] != f) continue;
      const size_t here = c++;
      if (!loop.alignment.inlier_mask[k]) continue;
      const point3D_t old_id = window[f].old_points[here];
      const point3D_t recent_id = window[f].recent_points[here];
      edges.inlier_pairs.push_back({old_id, recent_id});
      for (const TrackElement& el : rec.GetPoint3D(old_id).track.elements) ++old_votes[el.image_id];
      for (const TrackElement& el : rec.GetPoint3D(recent_id).track.elements) {
        ++recent_votes[el.image_id];
      }
    }
    if (old_votes.empty() || recent_votes.empty()) continue;
    const auto end = std::make_pair(most_votes(old_votes), most_votes(recent_votes));
    const auto known = std::find(ends.begin(), ends.end(), end);
    if (known == ends.end()) {
      ends.push_back(end);
      edges.num_point_pairs.push_back(loop.frame_inliers[f]);
    } else {
      edges.num_point_pairs[known - ends.begin()] += loop.frame_inliers[f];
    }
  }
  auto world_from_cam = [&](image_t id) {
    return Sim3d::FromRigid(rec.GetImage(id).cam_from_world.Inverse());
  };
  for (const auto& [old_id, recent_id] : ends) {
    edges.edges.push_back({old_id, recent_id,
                           world_from_cam(old_id).Inverse() * loop.alignment.dst_from_src *
                               world_from_cam(recent_id)});
  }
  return edges;
}

bool LoopCloser::CorrectOrGather(MapperState& model, const LoopEdges& edges, ClosedLoop loop,
                                 MapperReport* report) {
  const Reconstruction& rec = model.reconstruction();
  loop.num_points_before = static_cast<long long>(rec.NumPoints3D());
  loop.num_points_after = loop.num_points_before;
  bool closed = false;
  if (refine_) {
    Timer timer;
    closed = Close(model, edges.edges, options_.loop_edge_weight, edges.inlier_pairs, report);
    loop.num_points_after = static_cast<long long>(rec.NumPoints3D());
    loop.seconds = timer.ElapsedSeconds();
    report->seconds_loop_closing += loop.seconds;
    report->seconds_loop_detection -= loop.seconds;  // counted once, as closing
  } else {
    gathered_.insert(gathered_.end(), edges.edges.begin(), edges.edges.end());
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
  for (size_t e = 0; e < edges.edges.size(); ++e) {
    report->loop_links.push_back({"posegraph", rec.GetImage(edges.edges[e].old_id).name,
                                  rec.GetImage(edges.edges[e].recent_id).name,
                                  edges.num_point_pairs[e]});
  }
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
  BuildPoseGraph(model, loop_edges, loop_weight, &graph, &ordered);
  const std::map<image_t, Sim3d> before = graph.Nodes();
  PoseGraphOptions pg_options;
  pg_options.num_threads = model.options().num_threads;
  if (!graph.Optimize(pg_options)) {
    spdlog::warn("loop: pose graph failed ({}); the model is left as it was",
                 graph.report().termination);
    return false;
  }
  MoveWithGraph(graph, before, &rec);
  const PoseGraphReport& solved = graph.report();
  spdlog::debug("loop: pose graph {} nodes, {} edges, {} iterations, {:.2f} s; {}",
                solved.num_nodes, solved.num_edges, solved.num_iterations, solved.time_s,
                StretchedStep(rec, ordered, before));
  // The loop's inlier pairs become one point each (ORB-SLAM's loop fusion): the pose graph
  // only approximates the correction, so few of them would agree to the pixel yet and merge
  // by themselves, and without points seen from both ends nothing in the refining bundle
  // holds the ends together, and it relaxes a large correction back towards the drift.
  // Observations a fused point cannot fit are dropped after the bundle.
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

void LoopCloser::BuildPoseGraph(const MapperState& model, const std::vector<LoopEdge>& loop_edges,
                                double loop_weight, PoseGraph* graph,
                                std::vector<image_t>* ordered) const {
  const Reconstruction& rec = model.reconstruction();
  for (const MapperFrame& frame : input_.frames) {
    const Image& image = rec.GetImage(frame.image_id);
    if (!image.registered) continue;
    graph->AddNode(frame.image_id, Sim3d::FromRigid(image.cam_from_world.Inverse()));
    ordered->push_back(frame.image_id);
  }
  auto add_measured_edge = [&](image_t a, image_t b, double weight) {
    graph->AddEdge({.node1 = a, .node2 = b, .measured = graph->RelativeFromNodes(a, b),
                    .rotation_weight = weight, .translation_weight = weight,
                    .scale_weight = weight});
  };
  // Co-visible pairs (sharing points in the map) keep the path's shape. Consecutive frames
  // keep it connected, weakly where they share no points: a registration that jumped onto
  // the old map must not hold the drifted end in place.
  std::map<std::pair<image_t, image_t>, int> shared_points;
  for (const MapperPair& pair : input_.pairs) {
    const image_t a = pair.pair.image_id1, b = pair.pair.image_id2;
    if (!graph->HasNode(a) || !graph->HasNode(b)) continue;
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
  for (size_t i = 0; i + 1 < ordered->size(); ++i) {
    const image_t a = (*ordered)[i], b = (*ordered)[i + 1];
    const auto it = shared_points.find({std::min(a, b), std::max(a, b)});
    if (it != shared_points.end() && it->second >= options_.covisibility_min_points) continue;
    add_measured_edge(a, b, 0.1);
  }
  const double w = loop_weight;
  for (const LoopEdge& edge : loop_edges) {
    graph->AddEdge({.node1 = edge.old_id, .node2 = edge.recent_id, .measured = edge.measured,
                    .rotation_weight = w, .translation_weight = w, .scale_weight = w});
  }
  const image_t gauge =
      model.GaugeFirst() != kInvalidImageId && graph->HasNode(model.GaugeFirst())
          ? model.GaugeFirst()
          : ordered->front();
  graph->SetConstant(gauge);
}

void LoopCloser::MoveWithGraph(const PoseGraph& graph, const std::map<image_t, Sim3d>& before,
                               Reconstruction* rec) const {
  // Points move with the observing frame in the middle of their track (capture order).
  for (auto& [id, point] : rec->Points3D()) {
    std::vector<std::pair<int, image_t>> observers;
    for (const TrackElement& el : point.track.elements) {
      observers.push_back({frame_index_.at(el.image_id), el.image_id});
    }
    std::nth_element(observers.begin(), observers.begin() + observers.size() / 2, observers.end());
    const image_t ref = observers[observers.size() / 2].second;
    point.xyz = graph.Node(ref) * (before.at(ref).Inverse() * point.xyz);
  }
  for (const auto& [id, node] : graph.Nodes()) {
    rec->GetImage(id).cam_from_world = node.ToRigid().Inverse();
  }
}

}  // namespace loopsfm
