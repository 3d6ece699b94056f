#pragma once
// One model of the incremental mapper: the reconstruction being grown, the link from every
// keypoint to its track, and the steps that grow and refine it (registration, triangulation,
// point merging and filtering, local and global bundle adjustment).
//
// A track may hold several 3D points: where an observation does not fit the track's point
// (at a loop closure, the recent end of a long track disagrees with the old one by the
// drift), it starts or joins another point of the same track instead of being dropped, and
// points of one track are merged again once their observations agree. A point's track is
// found through any of its observations, so nothing is cached that could go stale when
// points are deleted.

#include <functional>
#include <optional>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "loopsfm/estimators/bundle_adjustment.h"
#include "loopsfm/geometry/triangulation.h"
#include "loopsfm/math/random.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"
#include "loopsfm/sfm/mapper_checkpoint.h"

namespace loopsfm {

class MapperState {
 public:
  MapperState(const MapperInput& input, const IncrementalMapperOptions& options);

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

  // The two frames that fix the gauge (the initial pair): the first pose constant, one
  // centre coordinate of the second constant in local bundles; global bundles hold the
  // scale through the frame farthest from the first instead (ScaleGaugeImage).
  void SetGauge(image_t first, image_t second);
  image_t GaugeFirst() const { return gauge1_; }
  image_t GaugeSecond() const { return gauge2_; }

  // The model's state for a checkpoint (merge failures are the mapper's, left 0), and a
  // model restored from one (throws InputError when it does not fit the input).
  MapperCheckpoint::Model Save() const;
  void Restore(const MapperCheckpoint::Model& saved);

  // --- Structure ---------------------------------------------------------------------
  // Triangulates, extends or merges every track seen by the image (after it was
  // registered). Returns the number of observations added.
  size_t TriangulateImage(image_t image_id);
  // Same over all tracks (after a global bundle adjustment).
  size_t RetriangulateAll();
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

  // --- Capture order ----------------------------------------------------------------
  // Whether a frame within `window` frames of the image in capture order is registered.
  bool NearRegisteredFrame(image_t image_id, int window) const;
  // The 2D-3D correspondences an unregistered image has through its verified pairs with the
  // registered frames nearest to it in capture order (the two nearest within
  // registration_neighbour_window frames): its keypoint and the 3D point of the keypoint
  // matched in the other frame.
  std::vector<std::pair<point2D_t, point3D_t>> NeighbourCorrespondences(image_t image_id) const;
  // How a pose of the image fits those correspondences: a point fits when it reprojects
  // within abs_pose_max_error_px.
  struct NeighbourAgreement {
    int num_checked = 0;
    int num_fit = 0;
    // Enough shared points to judge, and fewer than half of them fit.
    bool Disagrees() const { return num_checked >= 20 && 2 * num_fit < num_checked; }
  };
  NeighbourAgreement AgreementWithNeighbours(
      image_t image_id, const Rigid3d& cam_from_world,
      const std::vector<std::pair<point2D_t, point3D_t>>& correspondences) const;

  // --- Registration and refinement (mapper_steps.cc) -----------------------------------
  // Registers an image from its 2D-3D correspondences (P3P in LO-RANSAC, pose refinement).
  // A pose that disagrees with the frames next to it in capture order (AgreementWith-
  // Neighbours) is estimated again from the points those frames observe, and refused when
  // that one disagrees too. Returns false, leaving the model unchanged, when too few
  // correspondences fit.
  bool RegisterImage(image_t image_id, Random& random, MapperReport* report);
  // Bundle over the image and the frames sharing most points with it, then filtering of
  // the points involved. Returns false when the solver failed (the model is unchanged).
  bool LocalBundle(image_t image_id, MapperReport* report);
  // What a global bundle holds beyond every registered frame and its points.
  struct GlobalBundleScope {
    // Extra terms, added once the problem is set up (loop closing's point constraints).
    std::function<void(BundleAdjuster&)> add_terms;
    // Only these points' observations enter (BundleAdjustmentConfig::RestrictToPoints).
    std::optional<std::unordered_set<point3D_t>> points;
    // Only these frames move, with the points they observe; the other frames stay fixed
    // where they observe those points (at most 4 observations a point, as in local bundles)
    // and hold the gauge, and the cameras' intrinsics stay fixed. Not set, or every
    // registered frame: the whole model.
    std::optional<std::vector<image_t>> frames;
    // Replace BundleAdjustmentOptions::Global()'s settle and function tolerances.
    std::optional<double> settle_tolerance;
    std::optional<double> function_tolerance;
  };
  // Bundle over all registered frames (or scope.frames). Returns false when the solver failed.
  bool GlobalBundle(MapperReport* report, const GlobalBundleScope& scope = {});
  // Global bundle, re-triangulation and merging of all tracks, filtering, and a second
  // bundle when those changed much (both bundles with `settle_tolerance` when set).
  void GlobalRefinement(MapperReport* report, std::optional<double> settle_tolerance = {});
  // The same over a window of frames (the most recently registered of a growing model):
  // a bundle that moves only them (GlobalBundleScope::frames), then their tracks
  // re-triangulated and merged and their points filtered, and a second bundle when those
  // changed much. Its cost follows the window, not the model.
  void WindowRefinement(const std::vector<image_t>& frames, MapperReport* report);
  // Global refinement after a correction moved the cameras far from the bundle's optimum
  // (a loop closed by the pose graph): first a bundle over the longest tracks only, then
  // the other points re-triangulated from the moved cameras, then GlobalRefinement ending
  // at LoopClosureOptions::polish_settle_tolerance. The first bundle ends at
  // `subset_function_tolerance` when set (else Ceres' default).
  void RefineAfterCorrection(MapperReport* report,
                             std::optional<double> subset_function_tolerance = {});
  // The first half of that: a global bundle over the points LongestTrackPoints(per_frame)
  // picks and `also` (with `add_terms`, ending at `function_tolerance` when set), then the
  // other points re-triangulated from the moved cameras.
  void SubsetBundle(MapperReport* report, int per_frame,
                    const std::function<void(BundleAdjuster&)>& add_terms = {},
                    const std::vector<point3D_t>& also = {},
                    std::optional<double> function_tolerance = {});
  // Well-triangulated points of the longest tracks, taken longest first while one of their
  // frames has fewer than `per_frame` of them: every frame keeps its best-observed points.
  std::unordered_set<point3D_t> LongestTrackPoints(int per_frame) const;
  // Moves each point to the position its observations give with the current poses
  // (multi-view triangulation; points it fails for stay where they are).
  void RepositionPoints(const std::vector<point3D_t>& point_ids);

 private:
  // The frame whose centre holds the scale in global bundles: the one farthest from gauge1_.
  image_t ScaleGaugeImage() const;
  // A whole-model bundle's cameras: constant, or refined as options_ ask (by the model's size).
  void SetIntrinsicsRefinement(BundleAdjustmentConfig* config,
                               BundleAdjustmentOptions* ba_options) const;
  // Priors holding self-calibrated or guessed focal lengths near their start
  // (focal_prior_sigma_log); sets the adjuster up.
  void AddFocalPriors(const BundleAdjustmentConfig& config, BundleAdjuster& adjuster);
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
  double MaxAngularErrorRad(camera_t camera_id) const;

  const MapperInput& input_;
  const IncrementalMapperOptions& options_;
  Reconstruction reconstruction_;
  // track_of_[image_id][point2D_idx] = track index or -1.
  std::unordered_map<image_t, std::vector<int>> track_of_;
  // Position of each frame in capture order, and the verified pairs of each frame.
  std::unordered_map<image_t, int> capture_index_;
  std::unordered_map<image_t, std::vector<const MapperPair*>> pairs_of_;
  // Capture indices of the frames of track t: track_frames_[track_frame_begin_[t] ..
  // track_frame_begin_[t + 1]).
  std::vector<int> track_frame_begin_, track_frames_;
  // Per input track, its keypoints linked to a 3D point; per frame (capture index), its
  // tracks with at least one. Brought up to date from reconstruction_'s link changes.
  std::vector<int> track_links_, linked_tracks_of_frame_;
  image_t gauge1_ = kInvalidImageId, gauge2_ = kInvalidImageId;
};

}  // namespace loopsfm
