#include "loopsfm/scene/reconstruction.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "loopsfm/util/errors.h"

namespace loopsfm {

void Reconstruction::AddCamera(const Camera& camera) {
  LOOPSFM_CHECK(camera.camera_id != kInvalidCameraId);
  cameras_[camera.camera_id] = camera;
}

void Reconstruction::AddImage(Image image) {
  LOOPSFM_CHECK(ExistsCamera(image.camera_id));
  LOOPSFM_CHECK(!ExistsImage(image.image_id));
  const image_t id = image.image_id;
  image.num_points3D = 0;
  for (const auto& p : image.points2D) image.num_points3D += p.HasPoint3D() ? 1 : 0;
  if (image.registered) reg_image_ids_.push_back(id);
  images_.emplace(id, std::move(image));
}

void Reconstruction::RegisterImage(image_t image_id) {
  Image& image = images_.at(image_id);
  if (image.registered) return;
  image.registered = true;
  reg_image_ids_.push_back(image_id);
}

void Reconstruction::DeRegisterImage(image_t image_id) {
  Image& image = images_.at(image_id);
  for (point2D_t idx = 0; idx < image.points2D.size(); ++idx) {
    if (image.points2D[idx].HasPoint3D()) DeleteObservation(image_id, idx);
  }
  image.registered = false;
  reg_image_ids_.erase(std::remove(reg_image_ids_.begin(), reg_image_ids_.end(), image_id),
                       reg_image_ids_.end());
}

point3D_t Reconstruction::AddPoint3D(const Eigen::Vector3d& xyz, const Track& track,
                                     const Eigen::Matrix<uint8_t, 3, 1>& color) {
  const point3D_t id = next_point3D_id_++;
  for (const TrackElement& el : track.elements) {
    Point2D& p = images_.at(el.image_id).points2D.at(el.point2D_idx);
    LOOPSFM_CHECK_MSG(!p.HasPoint3D(), "image {} point {} already has a 3D point", el.image_id,
                      el.point2D_idx);
    p.point3D_id = id;
    ++images_.at(el.image_id).num_points3D;
    NoteLink(el.image_id, el.point2D_idx, true);
  }
  Point3D& point = points3D_[id];
  point.xyz = xyz;
  point.track = track;
  point.color = color;
  return id;
}

void Reconstruction::AddObservation(point3D_t point3D_id, const TrackElement& el) {
  Image& image = images_.at(el.image_id);
  Point2D& p = image.points2D.at(el.point2D_idx);
  LOOPSFM_CHECK(!p.HasPoint3D());
  p.point3D_id = point3D_id;
  ++image.num_points3D;
  NoteLink(el.image_id, el.point2D_idx, true);
  points3D_.at(point3D_id).track.elements.push_back(el);
}

void Reconstruction::DeleteObservation(image_t image_id, point2D_t point2D_idx) {
  Image& image = images_.at(image_id);
  const point3D_t id = image.points2D.at(point2D_idx).point3D_id;
  LOOPSFM_CHECK(id != kInvalidPoint3DId);
  Point3D& point = points3D_.at(id);
  if (point.track.Length() <= 2) {
    DeletePoint3D(id);
    return;
  }
  auto& elements = point.track.elements;
  elements.erase(std::remove(elements.begin(), elements.end(), TrackElement{image_id, point2D_idx}),
                 elements.end());
  image.points2D[point2D_idx].point3D_id = kInvalidPoint3DId;
  --image.num_points3D;
  NoteLink(image_id, point2D_idx, false);
}

void Reconstruction::DeletePoint3D(point3D_t point3D_id) {
  const Point3D& point = points3D_.at(point3D_id);
  for (const TrackElement& el : point.track.elements) {
    Image& image = images_.at(el.image_id);
    image.points2D.at(el.point2D_idx).point3D_id = kInvalidPoint3DId;
    --image.num_points3D;
    NoteLink(el.image_id, el.point2D_idx, false);
  }
  points3D_.erase(point3D_id);
}

point3D_t Reconstruction::MergePoints3D(point3D_t id1, point3D_t id2) {
  const Point3D& p1 = points3D_.at(id1);
  const Point3D& p2 = points3D_.at(id2);
  const double w1 = static_cast<double>(p1.track.Length());
  const double w2 = static_cast<double>(p2.track.Length());
  const Eigen::Vector3d xyz = (w1 * p1.xyz + w2 * p2.xyz) / (w1 + w2);
  const Eigen::Vector3d color =
      (w1 * p1.color.cast<double>() + w2 * p2.color.cast<double>()) / (w1 + w2);
  Track track = p1.track;
  track.elements.insert(track.elements.end(), p2.track.elements.begin(), p2.track.elements.end());
  DeletePoint3D(id1);
  DeletePoint3D(id2);
  return AddPoint3D(xyz, track, color.array().round().cast<uint8_t>());
}

std::vector<image_t> Reconstruction::RegImageIds() const {
  std::vector<image_t> ids = reg_image_ids_;
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::vector<point3D_t> Reconstruction::Point3DIds() const {
  std::vector<point3D_t> ids;
  ids.reserve(points3D_.size());
  for (const auto& [id, point] : points3D_) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

MappedState Reconstruction::SaveMapped() const {
  MappedState state;
  for (const auto& [id, camera] : cameras_) state.cameras.push_back(camera);
  std::sort(state.cameras.begin(), state.cameras.end(),
            [](const Camera& a, const Camera& b) { return a.camera_id < b.camera_id; });
  for (const image_t id : reg_image_ids_) {
    state.registered.push_back({id, images_.at(id).cam_from_world});
  }
  for (const point3D_t id : Point3DIds()) {
    const Point3D& point = points3D_.at(id);
    state.points.push_back({id, point.xyz, point.color, point.error, point.track.elements});
  }
  state.next_point3D_id = next_point3D_id_;
  return state;
}

void Reconstruction::RestoreMapped(const MappedState& state) {
  LOOPSFM_CHECK_MSG(reg_image_ids_.empty() && points3D_.empty(),
                    "RestoreMapped needs a reconstruction with nothing registered");
  for (const Camera& camera : state.cameras) {
    const auto it = cameras_.find(camera.camera_id);
    if (it == cameras_.end() || it->second.model_id != camera.model_id ||
        it->second.width != camera.width || it->second.height != camera.height ||
        it->second.params.size() != camera.params.size()) {
      throw InputError(fmt::format("saved camera {} ({} {}x{}) is not one of the input's",
                                   camera.camera_id, camera.ModelName(), camera.width,
                                   camera.height));
    }
    camera.Check();
    if (!std::all_of(camera.params.begin(), camera.params.end(),
                     [](double p) { return std::isfinite(p); })) {
      throw InputError(fmt::format("saved camera {} has parameters that are not finite",
                                   camera.camera_id));
    }
    it->second = camera;
  }
  for (const MappedState::RegisteredImage& r : state.registered) {
    const auto it = images_.find(r.image_id);
    if (it == images_.end() || it->second.registered) {
      throw InputError(fmt::format("saved frame {} is not an input frame, or appears twice",
                                   r.image_id));
    }
    if (!r.cam_from_world.rotation.coeffs().allFinite() ||
        !r.cam_from_world.translation.allFinite() ||
        std::abs(r.cam_from_world.rotation.norm() - 1.0) > 1e-6) {
      throw InputError(fmt::format("saved pose of frame {} is not a finite rotation and "
                                   "translation", r.image_id));
    }
    it->second.cam_from_world = r.cam_from_world;
    RegisterImage(r.image_id);
  }
  point3D_t next_id = state.next_point3D_id;
  for (const MappedState::SavedPoint& saved : state.points) {
    if (saved.point3D_id == kInvalidPoint3DId || points3D_.count(saved.point3D_id) > 0 ||
        saved.track.size() < 2 || !saved.xyz.allFinite()) {
      throw InputError(fmt::format("saved 3D point {} is invalid, repeated, not finite or has "
                                   "fewer than two observations", saved.point3D_id));
    }
    for (const TrackElement& el : saved.track) {
      const auto it = images_.find(el.image_id);
      if (it == images_.end() || !it->second.registered ||
          el.point2D_idx >= it->second.points2D.size() ||
          it->second.points2D[el.point2D_idx].HasPoint3D()) {
        throw InputError(fmt::format("saved 3D point {} is observed by keypoint {} of frame {}, "
                                     "which is not a free keypoint of a registered frame",
                                     saved.point3D_id, el.point2D_idx, el.image_id));
      }
      Image& image = it->second;
      image.points2D[el.point2D_idx].point3D_id = saved.point3D_id;
      ++image.num_points3D;
      NoteLink(el.image_id, el.point2D_idx, true);
    }
    Point3D& point = points3D_[saved.point3D_id];
    point.xyz = saved.xyz;
    point.color = saved.color;
    point.error = saved.error;
    point.track.elements = saved.track;
    next_id = std::max(next_id, saved.point3D_id + 1);
  }
  next_point3D_id_ = next_id;
}

std::optional<double> Reconstruction::ReprojectionError(const Point3D& point,
                                                        const TrackElement& el) const {
  const Image& image = images_.at(el.image_id);
  const Eigen::Vector3d in_cam = image.cam_from_world * point.xyz;
  if (in_cam.z() <= std::numeric_limits<double>::epsilon()) return std::nullopt;
  const Eigen::Vector2d projected = cameras_.at(image.camera_id).ImgFromCam(in_cam);
  return (projected - image.points2D.at(el.point2D_idx).xy).norm();
}

double Reconstruction::UpdateReprojectionErrors() {
  double sum = 0.0;
  size_t count = 0;
  for (auto& [id, point] : points3D_) {
    double point_sum = 0.0;
    size_t point_count = 0;
    for (const TrackElement& el : point.track.elements) {
      if (const auto error = ReprojectionError(point, el)) {
        point_sum += *error;
        ++point_count;
      }
    }
    point.error = point_count > 0 ? point_sum / point_count : -1.0;
    sum += point_sum;
    count += point_count;
  }
  return count > 0 ? sum / count : 0.0;
}

size_t Reconstruction::ComputeNumObservations() const {
  size_t n = 0;
  for (const auto& [id, point] : points3D_) n += point.track.Length();
  return n;
}

double Reconstruction::ComputeMeanTrackLength() const {
  return points3D_.empty() ? 0.0 : double(ComputeNumObservations()) / points3D_.size();
}

double Reconstruction::ComputeMeanObservationsPerRegImage() const {
  return reg_image_ids_.empty() ? 0.0 : double(ComputeNumObservations()) / reg_image_ids_.size();
}

void Reconstruction::Transform(const Sim3d& new_from_old) {
  for (auto& [id, image] : images_) {
    if (image.registered) image.cam_from_world = TransformCamFromWorld(image.cam_from_world, new_from_old);
  }
  for (auto& [id, point] : points3D_) point.xyz = new_from_old * point.xyz;
}

Reconstruction Reconstruction::Subset(const std::vector<image_t>& image_ids) const {
  const std::set<image_t> keep(image_ids.begin(), image_ids.end());
  Reconstruction subset;
  for (const auto& [id, camera] : cameras_) subset.AddCamera(camera);
  for (const auto& [id, image] : images_) {
    Image copy = image;
    for (auto& p : copy.points2D) p.point3D_id = kInvalidPoint3DId;
    copy.registered = image.registered && keep.count(id) > 0;
    subset.AddImage(std::move(copy));
  }
  for (const auto& [id, point] : points3D_) {
    Track track;
    for (const auto& el : point.track.elements) {
      if (keep.count(el.image_id) && images_.at(el.image_id).registered) track.elements.push_back(el);
    }
    if (track.Length() >= 2) subset.AddPoint3D(point.xyz, track, point.color);
  }
  return subset;
}

}  // namespace loopsfm
