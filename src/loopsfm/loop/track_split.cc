#include "loopsfm/loop/track_split.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "loopsfm/estimators/cost_functions/point_distance.h"
#include "loopsfm/loop/drift_correction.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/point_alignment.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// Capture indices of a point's observers: first, median, last.
struct Span {
  int first = 0, median = 0, last = 0;
};

struct SplitPair {
  point3D_t old_id = kInvalidPoint3DId, recent_id = kInvalidPoint3DId;
  Span old_span, recent_span;
};

// Capture indices of each input frame.
using FrameIndex = std::unordered_map<image_t, int>;

Span SpanOf(const Point3D& point, const FrameIndex& index) {
  std::vector<int> indices;
  for (const TrackElement& el : point.track.elements) indices.push_back(index.at(el.image_id));
  std::sort(indices.begin(), indices.end());
  return Span{indices.front(), indices[indices.size() / 2], indices.back()};
}

// The split pairs of the model (an old point, and a recent one seen only by frames at least
// `gap` later), grouped by the stretches of path their two ends lie on.
std::map<std::pair<int, int>, std::vector<SplitPair>> GroupSplitPairs(const MapperState& model,
                                                                      const FrameIndex& index,
                                                                      int gap) {
  const Reconstruction& rec = model.reconstruction();
  std::map<std::pair<int, int>, std::vector<SplitPair>> groups;
  std::unordered_set<int> tracks_done;
  for (const point3D_t id : rec.Point3DIds()) {
    const int track = model.TrackOfPoint(id);
    if (track < 0 || !tracks_done.insert(track).second) continue;
    const std::vector<point3D_t> points = model.PointsOfTrack(track);
    if (points.size() < 2) continue;
    std::vector<Span> spans;
    for (point3D_t p : points) spans.push_back(SpanOf(rec.GetPoint3D(p), index));
    for (size_t a = 0; a < points.size(); ++a) {
      for (size_t b = 0; b < points.size(); ++b) {
        if (a == b || spans[a].last + gap > spans[b].first) continue;
        groups[{spans[a].median / gap, spans[b].median / gap}].push_back(
            {points[a], points[b], spans[a], spans[b]});
      }
    }
  }
  return groups;
}

int MedianOf(std::vector<int> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// The pairs of one group that follow one similarity, when there are enough of them, they
// do not agree as they are already, and the correction is plausible as drift; none
// otherwise. Counts the group in the report as kept or refused.
std::vector<SplitPair> DriftPairs(const MapperState& model, const std::vector<SplitPair>& pairs,
                                  const LoopClosureOptions& options, Random& random,
                                  MapperReport* report) {
  if (static_cast<int>(pairs.size()) < options.min_num_inliers) return {};
  const MapperInput& input = model.input();
  const Reconstruction& rec = model.reconstruction();
  std::vector<PointCorrespondence> correspondences;
  for (const SplitPair& pair : pairs) {
    const Point3D& recent = rec.GetPoint3D(pair.recent_id);
    const Point3D& old = rec.GetPoint3D(pair.old_id);
    correspondences.push_back(
        {recent.xyz, old.xyz, FirstObservation(rec, recent), FirstObservation(rec, old)});
  }
  const PointAlignment alignment =
      AlignPointSets(correspondences, options.max_reproj_error_px, 2000, random);
  if (!alignment.success || alignment.num_inliers < options.min_num_inliers ||
      alignment.num_inliers < options.min_inlier_ratio * pairs.size()) {
    return {};
  }
  // Pairs that agree as they are merge by re-triangulation; nothing to tie.
  const std::vector<char> as_is =
      AlignmentInliers(correspondences, Sim3d(), options.max_reproj_error_px);
  std::vector<int> old_medians, recent_medians;
  std::vector<SplitPair> inliers;
  int agree_as_is = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    if (!alignment.inlier_mask[k]) continue;
    agree_as_is += as_is[k];
    old_medians.push_back(pairs[k].old_span.median);
    recent_medians.push_back(pairs[k].recent_span.median);
    inliers.push_back(pairs[k]);
  }
  if (agree_as_is >= 0.5 * alignment.num_inliers) return {};
  const int old_index = MedianOf(std::move(old_medians));
  const int recent_index = MedianOf(std::move(recent_medians));
  const image_t recent_frame = input.frames[recent_index].image_id;
  if (!rec.IsRegistered(recent_frame)) return {};
  const DriftCorrection correction = MeasureCorrection(
      rec, input, alignment.dst_from_src, recent_frame, old_index, recent_index, options);
  const std::string ends = input.frames[recent_index].name + " -> " + input.frames[old_index].name;
  if (!correction.plausible) {
    ++report->num_split_groups_refused;
    spdlog::info("split: refused {} pairs {}: a correction of {:.3g} ({:.1f} % of the path "
                 "between), scale {:.3f}, is too large for drift",
                 alignment.num_inliers, ends, correction.translation,
                 100.0 * correction.fraction_of_path, correction.scale);
    return {};
  }
  ++report->num_split_groups;
  spdlog::info("split: {} of {} pairs {} follow one similarity (moves the recent end {:.3g}, "
               "{:.2f} % of the path between, scale {:.4f})",
               alignment.num_inliers, pairs.size(), ends, correction.translation,
               100.0 * correction.fraction_of_path, correction.scale);
  return inliers;
}

// The tied pairs' coincidence terms in a bundle adjustment (track_split.h), then the
// re-triangulation that merges them and a full bundle without them. `sample`: the pairs
// (index in `tied`, weight scale) of the first bundle over the longest tracks.
void TieAndRefine(MapperState& model, const std::vector<SplitPair>& tied,
                  const std::vector<std::pair<size_t, double>>& sample,
                  const LoopClosureOptions& options, MapperReport* report) {
  const MapperInput& input = model.input();
  const Reconstruction& rec = model.reconstruction();
  // A pair's tie, its weight times `scale`: the two points' separation as the old point's
  // median observer sees it (in pixels, about), so that the ties cannot pull the model's
  // scale down (a tie in world units gets cheaper as the model shrinks; with the gauge held
  // at the first frames, a bundle then tore those off and shrank the rest).
  const auto tie = [&](BundleAdjuster& adjuster, const SplitPair& pair, double scale) {
    const Point3D& old = rec.GetPoint3D(pair.old_id);
    const Point3D& recent = rec.GetPoint3D(pair.recent_id);
    const image_t observer_id = input.frames[pair.old_span.median].image_id;
    const Image& observer = rec.GetImage(observer_id);
    if ((observer.cam_from_world * (0.5 * (old.xyz + recent.xyz))).z() <= 0.0) return;
    const double focal = rec.GetCamera(observer.camera_id).MeanFocalLength();
    adjuster.problem().AddResidualBlock(
        DepthScaledCoincidenceCost::Create(scale * options.split_weight * focal), nullptr,
        adjuster.PointBlock(pair.old_id), adjuster.PointBlock(pair.recent_id),
        adjuster.PoseBlock(observer_id));
  };
  // As after a pose-graph correction, the cameras start far from where the ties take them:
  // a bundle over the longest tracks moves them first. A tied point is not eliminated with
  // the others in the Schur complement (its tie links it to another point), so thousands of
  // ties make that bundle's camera system large; the sample moves the cameras as far.
  // Without that bundle (refine_points_per_frame 0), every tie enters one full bundle.
  std::optional<double> polish;
  if (options.refine_points_per_frame > 0) {
    std::vector<point3D_t> sample_points;
    for (const auto& [k, scale] : sample) {
      sample_points.push_back(tied[k].old_id);
      sample_points.push_back(tied[k].recent_id);
    }
    model.SubsetBundle(
        report, options.refine_points_per_frame,
        [&](BundleAdjuster& adjuster) {
          for (const auto& [k, scale] : sample) tie(adjuster, tied[k], scale);
        },
        sample_points);
    polish = options.polish_settle_tolerance;
  } else {
    model.GlobalBundle(report, {.add_terms = [&](BundleAdjuster& adjuster) {
                                  for (const SplitPair& pair : tied) tie(adjuster, pair, 1.0);
                                }});
  }
  // The tied points now agree and merge into one point each: from here on the fused tracks
  // hold the two ends together, and the full bundle polishes without ties.
  model.RetriangulateAll();
  model.FilterPoints({});
  model.GlobalBundle(report, {.settle_tolerance = polish});
  model.FilterPoints({});
}

}  // namespace

int CloseLoopsBySplitTracks(MapperState& model, const LoopClosureOptions& options, Random& random,
                            MapperReport* report) {
  Timer timer;
  const MapperInput& input = model.input();
  const Reconstruction& rec = model.reconstruction();
  FrameIndex index;
  for (size_t i = 0; i < input.frames.size(); ++i) index[input.frames[i].image_id] = static_cast<int>(i);
  std::vector<SplitPair> tied;
  // Up to split_refine_ties_per_group pairs of each group for the first bundle, each weighted
  // to pull as hard as the group's share it stands for: (index in `tied`, weight scale).
  std::vector<std::pair<size_t, double>> sample;
  for (const auto& [key, pairs] : GroupSplitPairs(model, index, options.min_frame_gap)) {
    const std::vector<SplitPair> drift = DriftPairs(model, pairs, options, random, report);
    if (drift.empty()) continue;
    const size_t first = tied.size();
    tied.insert(tied.end(), drift.begin(), drift.end());
    const size_t take = std::min<size_t>(options.split_refine_ties_per_group, drift.size());
    const double scale = std::sqrt(static_cast<double>(drift.size()) / take);
    for (size_t k = 0; k < take; ++k) sample.push_back({first + k * drift.size() / take, scale});
  }
  report->num_split_pairs += static_cast<int>(tied.size());
  if (tied.empty()) {
    report->seconds_split += timer.ElapsedSeconds();
    return 0;
  }
  std::map<std::pair<int, int>, int> links;  // (old, recent median observer) -> pairs
  for (const SplitPair& pair : tied) ++links[{pair.old_span.median, pair.recent_span.median}];
  for (const auto& [frames, num_pairs] : links) {
    report->loop_links.push_back({"split", input.frames[frames.first].name,
                                  input.frames[frames.second].name, num_pairs});
  }
  KeepPathBeforeLoopClosing(input, rec, report);
  const size_t points_before = rec.NumPoints3D();
  TieAndRefine(model, tied, sample, options, report);
  const double seconds = timer.ElapsedSeconds();
  report->seconds_split += seconds;
  spdlog::info("split: {} pairs tied in {} groups; points {} -> {}, {:.1f} s", tied.size(),
               report->num_split_groups, points_before, rec.NumPoints3D(), seconds);
  return static_cast<int>(tied.size());
}

}  // namespace loopsfm
