#pragma once
// A sparse reconstruction: cameras, images with poses and 2D points, and 3D points with
// their tracks. The mapper grows it; exporters and evaluation read it. Single-threaded.

#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/camera.h"
#include "loopsfm/scene/track.h"

namespace loopsfm {

struct Point2D {
  // COLMAP pixel convention.
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
  point3D_t point3D_id = kInvalidPoint3DId;
  bool HasPoint3D() const { return point3D_id != kInvalidPoint3DId; }
};

struct Image {
  image_t image_id = kInvalidImageId;
  camera_t camera_id = kInvalidCameraId;
  std::string name;
  // Valid when registered.
  Rigid3d cam_from_world;
  bool registered = false;
  std::vector<Point2D> points2D;
  // Number of points2D with a 3D point.
  size_t num_points3D = 0;

  Eigen::Vector3d ProjectionCenter() const { return cam_from_world.Inverse().translation; }
  // Unit viewing direction (camera z axis) in world coordinates.
  Eigen::Vector3d ViewingDirection() const {
    return cam_from_world.rotation.inverse() * Eigen::Vector3d::UnitZ();
  }
};

struct Point3D {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  // RGB.
  Eigen::Matrix<uint8_t, 3, 1> color = Eigen::Matrix<uint8_t, 3, 1>::Zero();
  // Mean reprojection error in pixels, -1 when unknown.
  double error = -1.0;
  Track track;
};

// What mapping changes in a reconstruction whose cameras and images come from elsewhere
// (the database): the intrinsics, the registered frames with their poses, in registration
// order, and the 3D points with their ids and the next id. Restoring it reproduces the
// reconstruction exactly (the mapper's checkpoints).
struct MappedState {
  struct RegisteredImage {
    image_t image_id = kInvalidImageId;
    Rigid3d cam_from_world;
  };
  struct SavedPoint {
    point3D_t point3D_id = kInvalidPoint3DId;
    Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
    Eigen::Matrix<uint8_t, 3, 1> color = Eigen::Matrix<uint8_t, 3, 1>::Zero();
    double error = -1.0;
    std::vector<TrackElement> track;
  };
  std::vector<Camera> cameras;
  std::vector<RegisteredImage> registered;
  std::vector<SavedPoint> points;  // by id
  point3D_t next_point3D_id = 1;
};

class Reconstruction {
 public:
  // Cameras and images are added unregistered; ids come from the database.
  void AddCamera(const Camera& camera);
  void AddImage(Image image);

  void RegisterImage(image_t image_id);
  // Deregisters and removes the image's observations from all 3D points (points left with
  // fewer than two observations are deleted).
  void DeRegisterImage(image_t image_id);

  point3D_t AddPoint3D(const Eigen::Vector3d& xyz, const Track& track,
                       const Eigen::Matrix<uint8_t, 3, 1>& color = {});
  void AddObservation(point3D_t point3D_id, const TrackElement& element);
  // Removes one observation; deletes the point when fewer than two remain.
  void DeleteObservation(image_t image_id, point2D_t point2D_idx);
  void DeletePoint3D(point3D_t point3D_id);
  // Merges two points into one (track union, position weighted by track length).
  point3D_t MergePoints3D(point3D_t point3D_id1, point3D_t point3D_id2);

  bool ExistsCamera(camera_t id) const { return cameras_.count(id) > 0; }
  bool ExistsImage(image_t id) const { return images_.count(id) > 0; }
  bool ExistsPoint3D(point3D_t id) const { return points3D_.count(id) > 0; }
  const Camera& GetCamera(camera_t id) const { return cameras_.at(id); }
  Camera& GetCamera(camera_t id) { return cameras_.at(id); }
  const Image& GetImage(image_t id) const { return images_.at(id); }
  Image& GetImage(image_t id) { return images_.at(id); }
  const Point3D& GetPoint3D(point3D_t id) const { return points3D_.at(id); }
  Point3D& GetPoint3D(point3D_t id) { return points3D_.at(id); }

  const std::unordered_map<camera_t, Camera>& Cameras() const { return cameras_; }
  std::unordered_map<camera_t, Camera>& Cameras() { return cameras_; }
  const std::map<image_t, Image>& Images() const { return images_; }
  const std::unordered_map<point3D_t, Point3D>& Points3D() const { return points3D_; }
  std::unordered_map<point3D_t, Point3D>& Points3D() { return points3D_; }

  size_t NumImages() const { return images_.size(); }
  size_t NumRegImages() const { return reg_image_ids_.size(); }
  size_t NumPoints3D() const { return points3D_.size(); }
  // Registered image ids, in id order.
  std::vector<image_t> RegImageIds() const;
  // 3D point ids in id order: loops whose outcome depends on the order (random sampling,
  // points created as they go) iterate these, so a restored reconstruction behaves the same.
  std::vector<point3D_t> Point3DIds() const;

  MappedState SaveMapped() const;
  // Onto a reconstruction holding the same cameras and images with none registered and no
  // points (as the mapper starts). Throws InputError when the state does not fit them (a
  // camera, image or keypoint it names is missing, or a keypoint is observed twice).
  void RestoreMapped(const MappedState& state);
  bool IsRegistered(image_t id) const { return images_.at(id).registered; }

  // Pixel reprojection error of one observation; nullopt when the point is behind the camera.
  std::optional<double> ReprojectionError(const Point3D& point, const TrackElement& element) const;
  // Recomputes Point3D::error for every point and returns the mean over observations.
  double UpdateReprojectionErrors();
  double ComputeMeanTrackLength() const;
  double ComputeMeanObservationsPerRegImage() const;
  size_t ComputeNumObservations() const;

  // Applies a similarity transform to all poses and points (new_world_from_old_world).
  void Transform(const Sim3d& new_from_old);

  // Splits into connected parts is the mapper's business; this only copies the subset of
  // registered images given, with the points they observe (for exporting several models).
  Reconstruction Subset(const std::vector<image_t>& image_ids) const;

  // A keypoint linked to a 3D point or unlinked from one.
  struct LinkChange {
    image_t image_id;
    point2D_t point2D_idx;
    bool linked;
  };
  // From now on, records every change of a keypoint's link to a 3D point (AddPoint3D,
  // AddObservation, DeleteObservation, DeletePoint3D, MergePoints3D, RestoreMapped, and so
  // DeRegisterImage), so that a caller can keep counts over the model up to date instead of
  // walking every point (the mapper's ranking of the next frame). Off until called.
  void RecordLinkChanges() { record_links_ = true; }
  // The changes recorded since the last call, oldest first; clears them.
  std::vector<LinkChange> TakeLinkChanges() { return std::exchange(link_changes_, {}); }

 private:
  void NoteLink(image_t image_id, point2D_t point2D_idx, bool linked) {
    if (record_links_) link_changes_.push_back({image_id, point2D_idx, linked});
  }

  std::unordered_map<camera_t, Camera> cameras_;
  std::map<image_t, Image> images_;
  std::unordered_map<point3D_t, Point3D> points3D_;
  std::vector<image_t> reg_image_ids_;
  point3D_t next_point3D_id_ = 1;
  bool record_links_ = false;
  std::vector<LinkChange> link_changes_;
};

}  // namespace loopsfm
