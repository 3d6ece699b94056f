#include "loopsfm/sfm/model_merger.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/point_alignment.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm {
namespace {

std::vector<PointCorrespondence> CommonTrackPoints(const MapperState& dst, const MapperState& src) {
  const Reconstruction& d = dst.reconstruction();
  const Reconstruction& s = src.reconstruction();
  std::vector<PointCorrespondence> correspondences;
  for (const point3D_t id : s.Point3DIds()) {
    const Point3D& point = s.GetPoint3D(id);
    const int track = src.TrackOfPoint(id);
    for (point3D_t other : dst.PointsOfTrack(track)) {
      const Point3D& q = d.GetPoint3D(other);
      correspondences.push_back({point.xyz, q.xyz, FirstObservation(s, point), FirstObservation(d, q)});
    }
  }
  return correspondences;
}

}  // namespace

ModelMergeReport MergeModels(MapperState& dst, const MapperState& src, Random& random) {
  LOOPSFM_CHECK(&dst.input() == &src.input());
  const IncrementalMapperOptions& options = dst.options();
  ModelMergeReport report;
  const std::vector<PointCorrespondence> correspondences = CommonTrackPoints(dst, src);
  report.num_correspondences = static_cast<int>(correspondences.size());
  if (report.num_correspondences < options.merge_min_num_inliers) return report;

  const PointAlignment result =
      AlignPointSets(correspondences, options.merge_max_reproj_error_px, 2000, random);
  report.num_inliers = result.num_inliers;
  if (!result.success || result.num_inliers < options.merge_min_num_inliers ||
      result.num_inliers < options.merge_min_inlier_ratio * report.num_correspondences) {
    return report;
  }
  report.success = true;
  report.dst_from_src = result.dst_from_src;

  // Frames the destination lacks, with their moved poses.
  Reconstruction& d = dst.reconstruction();
  const Reconstruction& s = src.reconstruction();
  for (image_t id : s.RegImageIds()) {
    if (d.IsRegistered(id)) continue;
    d.GetImage(id).cam_from_world = TransformCamFromWorld(s.GetImage(id).cam_from_world, result.dst_from_src);
    d.RegisterImage(id);
    ++report.num_images_added;
  }
  // Points: observations the destination has no point for join a point of their track they
  // fit, or make a point of their own.
  for (const point3D_t id : s.Point3DIds()) {
    const Point3D& point = s.GetPoint3D(id);
    std::vector<TrackElement> free;
    for (const TrackElement& el : point.track.elements) {
      if (!d.GetImage(el.image_id).points2D[el.point2D_idx].HasPoint3D()) free.push_back(el);
    }
    if (free.empty()) continue;
    const Eigen::Vector3d xyz = result.dst_from_src * point.xyz;
    bool joined = false;
    for (point3D_t other : dst.PointsOfTrack(src.TrackOfPoint(id))) {
      const Eigen::Vector3d& at = d.GetPoint3D(other).xyz;
      const bool fits = std::all_of(free.begin(), free.end(), [&](const TrackElement& el) {
        return dst.ReprojectionErrorPx(at, el) <= options.max_reproj_error_px;
      });
      if (!fits) continue;
      for (const TrackElement& el : free) d.AddObservation(other, el);
      ++report.num_points_joined;
      joined = true;
      break;
    }
    if (!joined && free.size() >= 2) {
      Track track;
      track.elements = free;
      d.AddPoint3D(xyz, track, point.color);
      ++report.num_points_added;
    }
  }
  return report;
}

}  // namespace loopsfm
