#pragma once
// Internal state of the incremental mapper for one model: the reconstruction being grown,
// and the link from every keypoint to its track. A 3D point is always made from one track,
// so a track's point is found through any registered observation of it; nothing is cached
// that could go stale when points are deleted.

#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/incremental_mapper.h"

namespace loopsfm {

class MapperState {
 public:
  MapperState(const MapperInput& input, const IncrementalMapperOptions& options);

  Reconstruction& reconstruction() { return reconstruction_; }
  const MapperInput& input() const { return input_; }
  const IncrementalMapperOptions& options() const { return options_; }

  // Track of keypoint idx of an image, or -1.
  int TrackOf(image_t image_id, point2D_t idx) const;
  // The 3D point made from track t, or kInvalidPoint3DId.
  point3D_t PointOfTrack(int track) const;

  // Triangulates or extends every track seen by the image (after it was registered).
  // Returns the number of observations added.
  size_t TriangulateImage(image_t image_id);
  // Same over all tracks with at least two registered observations (after global BA).
  size_t RetriangulateAll();
  // Deletes observations with a large reprojection error or behind the camera, then points
  // with a small triangulation angle. Over the given points, or all when empty.
  size_t FilterPoints(const std::vector<point3D_t>& point_ids);

  // For every unregistered image: how many of its keypoints see an existing 3D point.
  std::unordered_map<image_t, size_t> CountVisiblePoints() const;

 private:
  // Triangulates or extends one track; returns observations added.
  size_t TriangulateTrack(int track);
  bool ObservationFits(const Eigen::Vector3d& xyz, const TrackElement& element) const;
  double MaxAngularErrorRad(camera_t camera_id) const;

  const MapperInput& input_;
  const IncrementalMapperOptions& options_;
  Reconstruction reconstruction_;
  // track_of_[image_id][point2D_idx] = track index or -1.
  std::unordered_map<image_t, std::vector<int>> track_of_;
};

}  // namespace loopsfm
