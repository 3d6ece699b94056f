#pragma once
// The structure of one model: the reconstruction, the link from every keypoint to its
// track, and what makes and keeps its points (triangulation, point merging and filtering,
// the counts of tracks each unregistered frame sees).
//
// A track may hold several 3D points: where an observation does not fit the track's point
// (at a loop closure, the recent end of a long track disagrees with the old one by the
// drift), it starts or joins another point of the same track instead of being dropped, and
// points of one track are merged again once their observations agree. A point's track is
// found through any of its observations, so nothing is cached that could go stale when
// points are deleted.

#include <unordered_map>
#include <vector>

#include "loopsfm/geometry/triangulation.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"

namespace loopsfm {

class MapStructure {
 public:
  // Every input camera and frame, nothing registered; `input` and `options` must outlive it.
  MapStructure(const MapperInput& input, const IncrementalMapperOptions& options);

  Reconstruction& reconstruction() { return reconstruction_; }
  const Reconstruction& reconstruction() const { return reconstruction_; }
  const MapperInput& input() const { return input_; }
  const IncrementalMapperOptions& options() const { return options_; }

  // Track of keypoint idx of an image, or -1.
  int TrackOf(image_t image_id, point2D_t idx) const;
  // The original track a 3D point was made from.
  int TrackOfPoint(point3D_t point3D_id) const;
  int TrackOfPoint(const Point3D& point) const;
  // The 3D points made from track t (none, one, or several when parts of it disagree).
  std::vector<point3D_t> PointsOfTrack(int track) const;

  // Triangulates, extends or merges every track seen by the image (after it was
  // registered). Returns the number of observations added.
  size_t TriangulateImage(image_t image_id);
  // Same over all tracks (after a global bundle adjustment).
  size_t RetriangulateAll();
  // Same over the tracks the registered frames among `frames` see.
  size_t RetriangulateFrames(const std::vector<image_t>& frames);
  // Takes over the points of a model of the same frames whose poses are already here (made
  // over another input of them, whose tracks may be parts of this input's). Each point keeps
  // the observations of its largest share in one track of this input (at least two, on
  // registered frames, keypoints with no point here yet). A track of this input that spans
  // `min_joined_span` frames or more in capture order, beyond the frames of that share, may
  // have been joined from parts (the loop pairs of CloseLoopsAfterMapping): its point is
  // not taken. What is not taken stays free for triangulation. Returns the points taken.
  size_t TakePointsOf(const Reconstruction& model, int min_joined_span);
  // One point from two points of the same track, placed where their observations meet best
  // even where some do not fit yet (a bundle and FilterPoints are to follow). Returns the new
  // point's id, or kInvalidPoint3DId (nothing changed) when the two are not of one track.
  point3D_t FusePoints(point3D_t id1, point3D_t id2);
  // Deletes observations with a large reprojection error or behind the camera, then points
  // with a small triangulation angle. Over the given points, or all when empty.
  size_t FilterPoints(const std::vector<point3D_t>& point_ids);
  // For every image not registered here: how many tracks with a 3D point it sees. Kept up to
  // date from the model's link changes, so a call costs the changes since the last one and a
  // pass over the frames, not a walk over every point.
  std::unordered_map<image_t, size_t> CountVisibleTracks();
  // The same by walking every point of the model (tests compare the two).
  std::unordered_map<image_t, size_t> CountVisibleTracksByScan() const;
  // Reprojection error in pixels of a position in the image of an observation; infinity
  // behind the camera.
  double ReprojectionErrorPx(const Eigen::Vector3d& xyz, const TrackElement& element) const;

  // Moves each point to the position its observations give with the current poses
  // (multi-view triangulation; points it fails for stay where they are).
  void RepositionPoints(const std::vector<point3D_t>& point_ids);

 protected:
  const MapperInput& input_;
  const IncrementalMapperOptions& options_;
  Reconstruction reconstruction_;
  // Position of each frame in capture order.
  std::unordered_map<image_t, int> capture_index_;

 private:
  // Triangulates, extends or merges one track; returns observations added.
  size_t TriangulateTrack(int track);
  // Starts new points from observations of a track that fit none of its points.
  size_t TriangulateNewPoints(std::vector<TrackElement> elements);
  // Merges points of one track when all their observations fit one position.
  void MergePointsOfTrack(int track);
  // Multi-view triangulation of these observations with the current poses, with no angle
  // or error bounds (where the point goes is all that is asked; callers check the fit).
  TriangulationReport PositionFromObservations(const std::vector<TrackElement>& elements) const;
  bool ObservationFits(const Eigen::Vector3d& xyz, const TrackElement& element) const;
  // Whether two of the observations see a point there under options_.min_tri_angle_deg or
  // more. Every point made, merged or kept passes this same test over all its observations,
  // so FilterPoints never deletes, with the poses unchanged, a point triangulation has just
  // made (which the next triangulation would then make again).
  bool WideEnough(const Eigen::Vector3d& xyz, const std::vector<TrackElement>& elements) const;
  double MaxAngularErrorRad(camera_t camera_id) const;

  // track_of_[image_id][point2D_idx] = track index or -1.
  std::unordered_map<image_t, std::vector<int>> track_of_;
  // Capture indices of the frames of track t: track_frames_[track_frame_begin_[t] ..
  // track_frame_begin_[t + 1]).
  std::vector<int> track_frame_begin_, track_frames_;
  // Per input track, its keypoints linked to a 3D point; per frame (capture index), its
  // tracks with at least one. Brought up to date from reconstruction_'s link changes.
  std::vector<int> track_links_, linked_tracks_of_frame_;
};

}  // namespace loopsfm
