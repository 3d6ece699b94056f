#include "loopsfm/sfm/mapper_state.h"

#include <algorithm>
#include <cmath>

#include "loopsfm/geometry/pose_checks.h"
#include "loopsfm/geometry/triangulation.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

MapperState::MapperState(const MapperInput& input, const IncrementalMapperOptions& options)
    : input_(input), options_(options) {
  for (const Camera& camera : input.cameras) reconstruction_.AddCamera(camera);
  for (const MapperFrame& frame : input.frames) {
    Image image;
    image.image_id = frame.image_id;
    image.camera_id = frame.camera_id;
    image.name = frame.name;
    image.points2D.resize(frame.points2D.size());
    for (size_t i = 0; i < frame.points2D.size(); ++i) image.points2D[i].xy = frame.points2D[i];
    reconstruction_.AddImage(std::move(image));
    track_of_[frame.image_id].assign(frame.points2D.size(), -1);
  }
  for (size_t t = 0; t < input.tracks.size(); ++t) {
    for (const TrackElement& el : input.tracks[t].elements) {
      auto it = track_of_.find(el.image_id);
      LOOPSFM_CHECK(it != track_of_.end() && el.point2D_idx < it->second.size());
      it->second[el.point2D_idx] = static_cast<int>(t);
    }
  }
}

int MapperState::TrackOf(image_t image_id, point2D_t idx) const {
  return track_of_.at(image_id)[idx];
}

point3D_t MapperState::PointOfTrack(int track) const {
  for (const TrackElement& el : input_.tracks[track].elements) {
    const Image& image = reconstruction_.GetImage(el.image_id);
    if (image.registered && image.points2D[el.point2D_idx].HasPoint3D()) {
      return image.points2D[el.point2D_idx].point3D_id;
    }
  }
  return kInvalidPoint3DId;
}

double MapperState::MaxAngularErrorRad(camera_t camera_id) const {
  return std::atan(options_.max_reproj_error_px /
                   reconstruction_.GetCamera(camera_id).MeanFocalLength());
}

bool MapperState::ObservationFits(const Eigen::Vector3d& xyz, const TrackElement& el) const {
  const Image& image = reconstruction_.GetImage(el.image_id);
  const Eigen::Vector3d in_cam = image.cam_from_world * xyz;
  if (in_cam.z() <= 1e-9) return false;
  const Eigen::Vector2d projected = reconstruction_.GetCamera(image.camera_id).ImgFromCam(in_cam);
  return (projected - image.points2D[el.point2D_idx].xy).norm() <= options_.max_reproj_error_px;
}

size_t MapperState::TriangulateTrack(int track) {
  std::vector<TrackElement> registered;
  for (const TrackElement& el : input_.tracks[track].elements) {
    if (reconstruction_.IsRegistered(el.image_id)) registered.push_back(el);
  }
  if (registered.size() < 2) return 0;

  const point3D_t existing = PointOfTrack(track);
  if (existing != kInvalidPoint3DId) {
    size_t added = 0;
    const Eigen::Vector3d xyz = reconstruction_.GetPoint3D(existing).xyz;
    for (const TrackElement& el : registered) {
      const Point2D& p = reconstruction_.GetImage(el.image_id).points2D[el.point2D_idx];
      if (!p.HasPoint3D() && ObservationFits(xyz, el)) {
        reconstruction_.AddObservation(existing, el);
        ++added;
      }
    }
    return added;
  }

  // New point: triangulate from all registered views; when an outlier view spoils that,
  // take the two-view solution that most views agree with and re-triangulate from those.
  std::vector<Matrix3x4d> poses;
  std::vector<Eigen::Vector2d> normalized;
  double max_angular_error = 0.0;
  for (const TrackElement& el : registered) {
    const Image& image = reconstruction_.GetImage(el.image_id);
    poses.push_back(image.cam_from_world.ToMatrix());
    normalized.push_back(
        reconstruction_.GetCamera(image.camera_id).CamFromImg(image.points2D[el.point2D_idx].xy));
    max_angular_error = std::max(max_angular_error, MaxAngularErrorRad(image.camera_id));
  }
  TriangulationOptions tri_options;
  tri_options.min_tri_angle_deg = options_.min_tri_angle_deg;
  tri_options.max_angular_error_deg = max_angular_error * 180.0 / M_PI;
  TriangulationReport result = TriangulateMultiViewChecked(poses, normalized, tri_options);
  std::vector<TrackElement> inliers = registered;
  if (result.status == TriangulationStatus::kLargeError && registered.size() > 2) {
    size_t best_count = 0;
    const size_t n = std::min<size_t>(registered.size(), 12);
    for (size_t i = 0; i < n; ++i) {
      for (size_t j = i + 1; j < n; ++j) {
        const std::array<Matrix3x4d, 2> pair_poses = {poses[i], poses[j]};
        const std::array<Eigen::Vector2d, 2> pair_points = {normalized[i], normalized[j]};
        const TriangulationReport two = TriangulateMultiViewChecked(pair_poses, pair_points, tri_options);
        if (!two.success()) continue;
        std::vector<TrackElement> agreeing;
        for (const TrackElement& el : registered) {
          if (ObservationFits(two.point3D_in_world, el)) agreeing.push_back(el);
        }
        if (agreeing.size() > best_count) {
          best_count = agreeing.size();
          inliers = std::move(agreeing);
        }
      }
    }
    if (best_count < 2) return 0;
    poses.clear();
    normalized.clear();
    for (const TrackElement& el : inliers) {
      const Image& image = reconstruction_.GetImage(el.image_id);
      poses.push_back(image.cam_from_world.ToMatrix());
      normalized.push_back(reconstruction_.GetCamera(image.camera_id)
                               .CamFromImg(image.points2D[el.point2D_idx].xy));
    }
    result = TriangulateMultiViewChecked(poses, normalized, tri_options);
  }
  if (!result.success()) return 0;
  Track track_in_model;
  track_in_model.elements = inliers;
  reconstruction_.AddPoint3D(result.point3D_in_world, track_in_model);
  return inliers.size();
}

size_t MapperState::TriangulateImage(image_t image_id) {
  size_t added = 0;
  for (int track : track_of_.at(image_id)) {
    if (track >= 0) added += TriangulateTrack(track);
  }
  return added;
}

size_t MapperState::RetriangulateAll() {
  size_t added = 0;
  for (size_t t = 0; t < input_.tracks.size(); ++t) added += TriangulateTrack(static_cast<int>(t));
  return added;
}

size_t MapperState::FilterPoints(const std::vector<point3D_t>& point_ids) {
  std::vector<point3D_t> ids = point_ids;
  if (ids.empty()) {
    for (const auto& [id, point] : reconstruction_.Points3D()) ids.push_back(id);
  }
  size_t removed = 0;
  const double min_angle = options_.min_tri_angle_deg * M_PI / 180.0;
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
    // Largest angle between viewing rays (checked over a bounded number of views).
    const auto& elements = reconstruction_.GetPoint3D(id).track.elements;
    const size_t n = std::min<size_t>(elements.size(), 30);
    double best = 0.0;
    for (size_t i = 0; i < n && best < min_angle; ++i) {
      const Eigen::Vector3d ci = reconstruction_.GetImage(elements[i].image_id).ProjectionCenter();
      for (size_t j = i + 1; j < n && best < min_angle; ++j) {
        const Eigen::Vector3d cj = reconstruction_.GetImage(elements[j].image_id).ProjectionCenter();
        best = std::max(best, CalculateTriangulationAngle(ci, cj, point.xyz));
      }
    }
    if (best < min_angle) {
      removed += elements.size();
      reconstruction_.DeletePoint3D(id);
    }
  }
  return removed;
}

std::unordered_map<image_t, size_t> MapperState::CountVisiblePoints() const {
  std::unordered_map<image_t, size_t> counts;
  for (const auto& [id, point] : reconstruction_.Points3D()) {
    const TrackElement& first = point.track.elements.front();
    const int track = TrackOf(first.image_id, first.point2D_idx);
    if (track < 0) continue;
    for (const TrackElement& el : input_.tracks[track].elements) {
      if (!reconstruction_.IsRegistered(el.image_id)) ++counts[el.image_id];
    }
  }
  return counts;
}

}  // namespace loopsfm
