#include "loopsfm/sfm/map_structure.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "loopsfm/geometry/triangulation.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

MapStructure::MapStructure(const MapperInput& input, const IncrementalMapperOptions& options)
    : input_(input), options_(options), reconstruction_(EmptyReconstruction(input)) {
  for (const MapperFrame& frame : input.frames) {
    track_of_[frame.image_id].assign(frame.points2D.size(), -1);
  }
  for (size_t k = 0; k < input.frames.size(); ++k) {
    capture_index_[input.frames[k].image_id] = static_cast<int>(k);
  }
  track_frame_begin_.reserve(input.tracks.size() + 1);
  track_frame_begin_.push_back(0);
  for (size_t t = 0; t < input.tracks.size(); ++t) {
    for (const TrackElement& el : input.tracks[t].elements) {
      auto it = track_of_.find(el.image_id);
      LOOPSFM_CHECK(it != track_of_.end() && el.point2D_idx < it->second.size());
      it->second[el.point2D_idx] = static_cast<int>(t);
      track_frames_.push_back(capture_index_.at(el.image_id));
    }
    track_frame_begin_.push_back(static_cast<int>(track_frames_.size()));
  }
  track_links_.assign(input.tracks.size(), 0);
  linked_tracks_of_frame_.assign(input.frames.size(), 0);
  reconstruction_.RecordLinkChanges();
}

int MapStructure::TrackOf(image_t image_id, point2D_t idx) const {
  return track_of_.at(image_id)[idx];
}

int MapStructure::TrackOfPoint(point3D_t point3D_id) const {
  return TrackOfPoint(reconstruction_.GetPoint3D(point3D_id));
}

int MapStructure::TrackOfPoint(const Point3D& point) const {
  const TrackElement& first = point.track.elements.front();
  return TrackOf(first.image_id, first.point2D_idx);
}

std::vector<point3D_t> MapStructure::PointsOfTrack(int track) const {
  std::vector<point3D_t> points;
  for (const TrackElement& el : input_.tracks[track].elements) {
    const Image& image = reconstruction_.GetImage(el.image_id);
    if (!image.registered) continue;
    const point3D_t id = image.points2D[el.point2D_idx].point3D_id;
    if (id != kInvalidPoint3DId && std::find(points.begin(), points.end(), id) == points.end()) {
      points.push_back(id);
    }
  }
  return points;
}

double MapStructure::MaxAngularErrorRad(camera_t camera_id) const {
  return std::atan(options_.max_reproj_error_px /
                   reconstruction_.GetCamera(camera_id).MeanFocalLength());
}

double MapStructure::ReprojectionErrorPx(const Eigen::Vector3d& xyz, const TrackElement& el) const {
  const Image& image = reconstruction_.GetImage(el.image_id);
  const Eigen::Vector3d in_cam = image.cam_from_world * xyz;
  if (in_cam.z() <= 1e-9) return std::numeric_limits<double>::infinity();
  const Eigen::Vector2d projected = reconstruction_.GetCamera(image.camera_id).ImgFromCam(in_cam);
  return (projected - image.points2D[el.point2D_idx].xy).norm();
}

bool MapStructure::ObservationFits(const Eigen::Vector3d& xyz, const TrackElement& el) const {
  return ReprojectionErrorPx(xyz, el) <= options_.max_reproj_error_px;
}

bool MapStructure::WideEnough(const Eigen::Vector3d& xyz,
                              const std::vector<TrackElement>& elements) const {
  std::vector<Eigen::Vector3d> rays;
  rays.reserve(elements.size());
  for (const TrackElement& el : elements) {
    rays.push_back((xyz - reconstruction_.GetImage(el.image_id).ProjectionCenter()).normalized());
  }
  return SomeRaysApart(rays, options_.min_tri_angle_deg * M_PI / 180.0);
}

size_t MapStructure::TriangulateTrack(int track) {
  std::vector<TrackElement> free;
  size_t num_registered = 0;
  for (const TrackElement& el : input_.tracks[track].elements) {
    const Image& image = reconstruction_.GetImage(el.image_id);
    if (!image.registered) continue;
    ++num_registered;
    if (!image.points2D[el.point2D_idx].HasPoint3D()) free.push_back(el);
  }
  if (free.empty() || num_registered < 2) return 0;

  // Each free observation joins the point of its track it fits best.
  const std::vector<point3D_t> points = PointsOfTrack(track);
  size_t added = 0;
  std::vector<TrackElement> unassigned;
  for (const TrackElement& el : free) {
    point3D_t best = kInvalidPoint3DId;
    double best_error = options_.max_reproj_error_px;
    for (point3D_t id : points) {
      const double error = ReprojectionErrorPx(reconstruction_.GetPoint3D(id).xyz, el);
      if (error <= best_error) {
        best = id;
        best_error = error;
      }
    }
    if (best != kInvalidPoint3DId) {
      reconstruction_.AddObservation(best, el);
      ++added;
    } else {
      unassigned.push_back(el);
    }
  }
  // The rest start points of their own.
  if (unassigned.size() >= 2) added += TriangulateNewPoints(std::move(unassigned));
  if (added > 0) MergePointsOfTrack(track);
  return added;
}

size_t MapStructure::TriangulateNewPoints(std::vector<TrackElement> elements) {
  TriangulationOptions tri_options;
  tri_options.min_tri_angle_deg = options_.min_tri_angle_deg;
  size_t added = 0;
  // A few rounds: each takes the largest set of observations one position explains.
  for (int round = 0; round < 3 && elements.size() >= 2; ++round) {
    std::vector<Matrix3x4d> poses;
    std::vector<Eigen::Vector2d> normalized;
    double max_angular_error = 0.0;
    for (const TrackElement& el : elements) {
      const Image& image = reconstruction_.GetImage(el.image_id);
      poses.push_back(image.cam_from_world.ToMatrix());
      normalized.push_back(
          reconstruction_.GetCamera(image.camera_id).CamFromImg(image.points2D[el.point2D_idx].xy));
      max_angular_error = std::max(max_angular_error, MaxAngularErrorRad(image.camera_id));
    }
    tri_options.max_angular_error_deg = max_angular_error * 180.0 / M_PI;
    TriangulationReport result = TriangulateMultiViewChecked(poses, normalized, tri_options);
    std::vector<TrackElement> inliers = elements;
    if (!result.success() && elements.size() > 2) {
      // An outlier view spoils the joint solution: take the two-view solution most views
      // agree with and re-triangulate from those.
      size_t best_count = 0;
      const size_t n = std::min<size_t>(elements.size(), 12);
      for (size_t i = 0; i < n; ++i) {
        for (size_t j = i + 1; j < n; ++j) {
          const std::array<Matrix3x4d, 2> pair_poses = {poses[i], poses[j]};
          const std::array<Eigen::Vector2d, 2> pair_points = {normalized[i], normalized[j]};
          const TriangulationReport two = TriangulateMultiViewChecked(pair_poses, pair_points, tri_options);
          if (!two.success()) continue;
          std::vector<TrackElement> agreeing;
          for (const TrackElement& el : elements) {
            if (ObservationFits(two.point3D_in_world, el)) agreeing.push_back(el);
          }
          if (agreeing.size() > best_count) {
            best_count = agreeing.size();
            inliers = std::move(agreeing);
          }
        }
      }
      if (best_count < 2) break;
      std::vector<Matrix3x4d> inlier_poses;
      std::vector<Eigen::Vector2d> inlier_points;
      for (const TrackElement& el : inliers) {
        const size_t k = std::find(elements.begin(), elements.end(), el) - elements.begin();
        inlier_poses.push_back(poses[k]);
        inlier_points.push_back(normalized[k]);
      }
      result = TriangulateMultiViewChecked(inlier_poses, inlier_points, tri_options);
    }
    if (!result.success()) break;
    // The angular test is looser than the pixel one away from the image centre.
    std::erase_if(inliers, [&](const TrackElement& el) { return !ObservationFits(result.point3D_in_world, el); });
    // The angle was checked over more views than remain.
    if (inliers.size() < 2 || !WideEnough(result.point3D_in_world, inliers)) break;
    Track track_in_model;
    track_in_model.elements = inliers;
    reconstruction_.AddPoint3D(result.point3D_in_world, track_in_model);
    added += inliers.size();
    std::erase_if(elements, [&](const TrackElement& el) {
      return std::find(inliers.begin(), inliers.end(), el) != inliers.end();
    });
  }
  return added;
}

void MapStructure::MergePointsOfTrack(int track) {
  bool merged = true;
  while (merged) {
    merged = false;
    const std::vector<point3D_t> points = PointsOfTrack(track);
    for (size_t a = 0; a < points.size() && !merged; ++a) {
      for (size_t b = a + 1; b < points.size() && !merged; ++b) {
        std::vector<TrackElement> elements = reconstruction_.GetPoint3D(points[a]).track.elements;
        const auto& more = reconstruction_.GetPoint3D(points[b]).track.elements;
        elements.insert(elements.end(), more.begin(), more.end());
        const TriangulationReport result = PositionFromObservations(elements);
        if (!result.success()) continue;
        const bool all_fit = std::all_of(elements.begin(), elements.end(), [&](const TrackElement& el) {
          return ObservationFits(result.point3D_in_world, el);
        });
        if (!all_fit || !WideEnough(result.point3D_in_world, elements)) continue;
        const point3D_t id = reconstruction_.MergePoints3D(points[a], points[b]);
        reconstruction_.GetPoint3D(id).xyz = result.point3D_in_world;
        merged = true;
      }
    }
  }
}

point3D_t MapStructure::FusePoints(point3D_t id1, point3D_t id2) {
  if (id1 == id2 || TrackOfPoint(id1) < 0 || TrackOfPoint(id1) != TrackOfPoint(id2)) {
    return kInvalidPoint3DId;
  }
  const point3D_t id = reconstruction_.MergePoints3D(id1, id2);
  Point3D& point = reconstruction_.GetPoint3D(id);
  const TriangulationReport result = PositionFromObservations(point.track.elements);
  if (result.success()) point.xyz = result.point3D_in_world;
  return id;
}

TriangulationReport MapStructure::PositionFromObservations(
    const std::vector<TrackElement>& elements) const {
  TriangulationOptions tri_options;
  tri_options.min_tri_angle_deg = 0.0;
  tri_options.max_angular_error_deg = 90.0;
  std::vector<Matrix3x4d> poses;
  std::vector<Eigen::Vector2d> normalized;
  for (const TrackElement& el : elements) {
    const Image& image = reconstruction_.GetImage(el.image_id);
    poses.push_back(image.cam_from_world.ToMatrix());
    normalized.push_back(reconstruction_.GetCamera(image.camera_id)
                             .CamFromImg(image.points2D[el.point2D_idx].xy));
  }
  return TriangulateMultiViewChecked(poses, normalized, tri_options);
}

size_t MapStructure::TriangulateImage(image_t image_id) {
  size_t added = 0;
  for (int track : track_of_.at(image_id)) {
    if (track >= 0) added += TriangulateTrack(track);
  }
  return added;
}

size_t MapStructure::RetriangulateAll() {
  size_t added = 0;
  for (size_t t = 0; t < input_.tracks.size(); ++t) {
    const int track = static_cast<int>(t);
    added += TriangulateTrack(track);
    // Positions moved in the bundle: points that disagreed before may agree now.
    MergePointsOfTrack(track);
  }
  return added;
}

size_t MapStructure::TakePointsOf(const Reconstruction& model, int min_joined_span) {
  // First and last frame of a track or of observations, in capture order.
  auto extent_of_track = [&](int track) {
    const auto [low, high] = std::minmax_element(track_frames_.begin() + track_frame_begin_[track],
                                                 track_frames_.begin() + track_frame_begin_[track + 1]);
    return std::make_pair(*low, *high);
  };
  auto extent_of = [&](const std::vector<TrackElement>& elements) {
    std::pair<int, int> extent{std::numeric_limits<int>::max(), -1};
    for (const TrackElement& el : elements) {
      const int index = capture_index_.at(el.image_id);
      extent = {std::min(extent.first, index), std::max(extent.second, index)};
    }
    return extent;
  };
  size_t taken = 0;
  std::map<int, std::vector<TrackElement>> by_track;
  for (const point3D_t id : model.Point3DIds()) {  // id order: the same points however made
    const Point3D& point = model.GetPoint3D(id);
    by_track.clear();
    for (const TrackElement& el : point.track.elements) {
      const Image& image = reconstruction_.GetImage(el.image_id);
      if (!image.registered || image.points2D[el.point2D_idx].HasPoint3D()) continue;
      const int track = TrackOf(el.image_id, el.point2D_idx);
      if (track >= 0) by_track[track].push_back(el);
    }
    const std::pair<const int, std::vector<TrackElement>>* largest = nullptr;
    for (const auto& entry : by_track) {
      if (!largest || entry.second.size() > largest->second.size()) largest = &entry;
    }
    if (!largest || largest->second.size() < 2) continue;
    const auto [first, last] = extent_of_track(largest->first);
    if (last - first >= min_joined_span && extent_of(largest->second) != std::make_pair(first, last)) {
      continue;  // the track reaches frames far from the point's: pairs there may have joined it
    }
    Track track;
    track.elements = largest->second;
    reconstruction_.AddPoint3D(point.xyz, track, point.color);
    ++taken;
  }
  return taken;
}

size_t MapStructure::RetriangulateFrames(const std::vector<image_t>& frames) {
  std::vector<int> tracks;
  for (image_t id : frames) {
    if (!reconstruction_.IsRegistered(id)) continue;
    for (int track : track_of_.at(id)) {
      if (track >= 0) tracks.push_back(track);
    }
  }
  std::sort(tracks.begin(), tracks.end());
  tracks.erase(std::unique(tracks.begin(), tracks.end()), tracks.end());
  size_t added = 0;
  for (int track : tracks) {
    added += TriangulateTrack(track);
    MergePointsOfTrack(track);
  }
  return added;
}

size_t MapStructure::FilterPoints(const std::vector<point3D_t>& point_ids) {
  std::vector<point3D_t> ids = point_ids;
  if (ids.empty()) {
    for (const auto& [id, point] : reconstruction_.Points3D()) ids.push_back(id);
  }
  size_t removed = 0;
  for (point3D_t id : ids) {
    if (!reconstruction_.ExistsPoint3D(id)) continue;
    const Point3D point = reconstruction_.GetPoint3D(id);
    for (const TrackElement& el : point.track.elements) {
      if (!ObservationFits(point.xyz, el)) {
        reconstruction_.DeleteObservation(el.image_id, el.point2D_idx);
        ++removed;
        if (!reconstruction_.ExistsPoint3D(id)) break;
      }
    }
    if (!reconstruction_.ExistsPoint3D(id)) continue;
    const Point3D& kept = reconstruction_.GetPoint3D(id);
    if (!WideEnough(kept.xyz, kept.track.elements)) {
      removed += kept.track.elements.size();
      reconstruction_.DeletePoint3D(id);
    }
  }
  return removed;
}

std::unordered_map<image_t, size_t> MapStructure::CountVisibleTracks() {
  for (const Reconstruction::LinkChange& change : reconstruction_.TakeLinkChanges()) {
    const int track = TrackOf(change.image_id, change.point2D_idx);
    if (track < 0) continue;
    // A track counts for its frames while at least one of its keypoints is linked.
    const int before = track_links_[track];
    track_links_[track] += change.linked ? 1 : -1;
    LOOPSFM_CHECK(track_links_[track] >= 0);
    const int delta = (track_links_[track] > 0) - (before > 0);
    if (delta == 0) continue;
    for (int e = track_frame_begin_[track]; e < track_frame_begin_[track + 1]; ++e) {
      linked_tracks_of_frame_[track_frames_[e]] += delta;
    }
  }
  std::unordered_map<image_t, size_t> visible;
  for (size_t k = 0; k < input_.frames.size(); ++k) {
    const image_t id = input_.frames[k].image_id;
    if (linked_tracks_of_frame_[k] > 0 && !reconstruction_.IsRegistered(id)) {
      visible[id] = static_cast<size_t>(linked_tracks_of_frame_[k]);
    }
  }
  return visible;
}

std::unordered_map<image_t, size_t> MapStructure::CountVisibleTracksByScan() const {
  const size_t num_frames = input_.frames.size();
  std::vector<char> registered(num_frames);
  for (size_t k = 0; k < num_frames; ++k) {
    registered[k] = reconstruction_.IsRegistered(input_.frames[k].image_id);
  }
  std::vector<size_t> counts(num_frames, 0);
  std::vector<char> seen(input_.tracks.size(), 0);
  for (const auto& [id, point] : reconstruction_.Points3D()) {
    const int track = TrackOfPoint(point);
    if (track < 0 || seen[track]) continue;
    seen[track] = 1;
    for (int e = track_frame_begin_[track]; e < track_frame_begin_[track + 1]; ++e) {
      if (!registered[track_frames_[e]]) ++counts[track_frames_[e]];
    }
  }
  std::unordered_map<image_t, size_t> visible;
  for (size_t k = 0; k < num_frames; ++k) {
    if (counts[k] > 0) visible[input_.frames[k].image_id] = counts[k];
  }
  return visible;
}

void MapStructure::RepositionPoints(const std::vector<point3D_t>& point_ids) {
  for (point3D_t id : point_ids) {
    Point3D& point = reconstruction_.GetPoint3D(id);
    const TriangulationReport result = PositionFromObservations(point.track.elements);
    if (result.success()) point.xyz = result.point3D_in_world;
  }
}

}  // namespace loopsfm
