#pragma once
// Internals shared by the binary (colmap_model.cc) and text (colmap_model_text.cc) COLMAP
// model readers and writers. Not part of the storage module's interface.

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/util/errors.h"

namespace loopsfm::colmap_model_internal {

namespace fs = std::filesystem;

inline std::ofstream OpenForWriting(const fs::path& dir, const char* name, bool binary) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  const fs::path path = dir / name;
  std::ofstream out(path, binary ? std::ios::binary | std::ios::out : std::ios::out);
  if (!out) {
    throw StorageError(
        fmt::format("cannot write '{}': check that the folder is writable", path.string()));
  }
  return out;
}

inline void FinishWriting(std::ofstream& out, const fs::path& path) {
  out.close();
  if (!out) throw StorageError(fmt::format("writing '{}' failed (disk full?)", path.string()));
}

inline std::vector<camera_t> SortedCameraIds(const Reconstruction& reconstruction) {
  std::vector<camera_t> ids;
  for (const auto& [id, camera] : reconstruction.Cameras()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

inline std::vector<point3D_t> SortedPoint3DIds(const Reconstruction& reconstruction) {
  std::vector<point3D_t> ids;
  for (const auto& [id, point] : reconstruction.Points3D()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

// Elements of a track whose image is written (registered).
inline std::vector<TrackElement> WrittenElements(const Reconstruction& reconstruction,
                                                 const Point3D& point) {
  std::vector<TrackElement> elements;
  for (const TrackElement& el : point.track.elements) {
    if (reconstruction.ExistsImage(el.image_id) && reconstruction.IsRegistered(el.image_id)) {
      elements.push_back(el);
    }
  }
  return elements;
}

// The 3D point id written for a 2D point (none when the point does not exist).
inline point3D_t WrittenPoint3DId(const Reconstruction& reconstruction, const Point2D& point2D) {
  return point2D.HasPoint3D() && reconstruction.ExistsPoint3D(point2D.point3D_id)
             ? point2D.point3D_id
             : kInvalidPoint3DId;
}

// Builds a Reconstruction from parsed records with the checks both readers need.
// `where` prefixes every error message (file, and line for text).
class ModelBuilder {
 public:
  void AddCamera(Camera camera, const std::string& where) {
    if (camera.camera_id == kInvalidCameraId || reconstruction_.ExistsCamera(camera.camera_id)) {
      throw InputError(
          fmt::format("{}: camera id {} is invalid or appears twice", where, camera.camera_id));
    }
    try {
      camera.Check();
    } catch (const InputError& e) {
      throw InputError(fmt::format("{}: camera {}: {}", where, camera.camera_id, e.what()));
    }
    reconstruction_.AddCamera(camera);
  }

  void AddImage(Image image, const std::string& where) {
    if (!reconstruction_.ExistsCamera(image.camera_id)) {
      throw InputError(
          fmt::format("{}: image {} ('{}') uses camera {}, which is not in the "
                      "cameras file",
                      where, image.image_id, image.name, image.camera_id));
    }
    if (image.image_id == kInvalidImageId || reconstruction_.ExistsImage(image.image_id)) {
      throw InputError(
          fmt::format("{}: image id {} is invalid or appears twice", where, image.image_id));
    }
    // Observations are restored from the tracks (see colmap_model.h).
    for (Point2D& p : image.points2D) p.point3D_id = kInvalidPoint3DId;
    image.registered = true;
    reconstruction_.AddImage(std::move(image));
  }

  void AddPoint3D(point3D_t file_id, Point3D point, const std::string& where) {
    for (const TrackElement& el : point.track.elements) {
      if (!reconstruction_.ExistsImage(el.image_id)) {
        throw InputError(
            fmt::format("{}: 3D point {} is observed by image {}, which is not in "
                        "the images file",
                        where, file_id, el.image_id));
      }
      const Image& image = reconstruction_.GetImage(el.image_id);
      if (el.point2D_idx >= image.points2D.size()) {
        throw InputError(
            fmt::format("{}: 3D point {} is observed by point {} of image {}, "
                        "which has only {} points",
                        where, file_id, el.point2D_idx, el.image_id, image.points2D.size()));
      }
    }
    points_.push_back({file_id, std::move(point), where});
  }

  Reconstruction Finish() {
    std::sort(points_.begin(), points_.end(),
              [](const PendingPoint& a, const PendingPoint& b) { return a.file_id < b.file_id; });
    for (size_t i = 1; i < points_.size(); ++i) {
      if (points_[i].file_id == points_[i - 1].file_id) {
        throw InputError(
            fmt::format("{}: 3D point id {} appears twice", points_[i].where, points_[i].file_id));
      }
    }
    for (PendingPoint& pending : points_) {
      std::vector<TrackElement> sorted = pending.point.track.elements;
      std::sort(sorted.begin(), sorted.end());
      for (size_t i = 0; i < sorted.size(); ++i) {
        const TrackElement& el = sorted[i];
        const bool repeated = i > 0 && sorted[i - 1] == el;
        if (repeated ||
            reconstruction_.GetImage(el.image_id).points2D[el.point2D_idx].HasPoint3D()) {
          throw InputError(
              fmt::format("{}: point {} of image {} observes more than one 3D point "
                          "(seen again in the track of 3D point {})",
                          pending.where, el.point2D_idx, el.image_id, pending.file_id));
        }
      }
      const point3D_t id =
          reconstruction_.AddPoint3D(pending.point.xyz, pending.point.track, pending.point.color);
      reconstruction_.GetPoint3D(id).error = pending.point.error;
    }
    return std::move(reconstruction_);
  }

 private:
  struct PendingPoint {
    point3D_t file_id;
    Point3D point;
    std::string where;
  };
  Reconstruction reconstruction_;
  std::vector<PendingPoint> points_;
};

}  // namespace loopsfm::colmap_model_internal
