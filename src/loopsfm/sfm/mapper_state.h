#pragma once
// One model of the incremental mapper: its structure (map_structure.h) and the steps that
// grow and refine it (registration of frames, local and global bundle adjustment).

#include <functional>
#include <optional>
#include <tuple>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "loopsfm/estimators/bundle_adjustment.h"
#include "loopsfm/math/random.h"
#include "loopsfm/sfm/map_structure.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"
#include "loopsfm/sfm/mapper_checkpoint.h"

namespace loopsfm {

class MapperState : public MapStructure {
 public:
  MapperState(const MapperInput& input, const IncrementalMapperOptions& options);

  // The two frames that fix the gauge (the initial pair): the first pose constant, one
  // centre coordinate of the second constant in local bundles; global bundles hold the
  // scale through the frame farthest from the first instead (ScaleGaugeImage).
  void SetGauge(image_t first, image_t second);
  image_t GaugeFirst() const { return gauge1_; }
  image_t GaugeSecond() const { return gauge2_; }

  // Takes over the poses of a model of the same frames (mapped from this input or a part of
  // it, InputPart): its cameras' intrinsics, and each of its registered frames registered
  // here at its pose, in capture order; the gauge goes to the first two. No point is
  // triangulated. Returns the frames taken, in capture order.
  std::vector<image_t> TakeFramesOf(const Reconstruction& model);

  // The model's state for a checkpoint (merge failures are the mapper's, left 0), and a
  // model restored from one (throws InputError when it does not fit the input).
  MapperCheckpoint::Model Save() const;
  void Restore(const MapperCheckpoint::Model& saved);

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
  // After `image_id` registered and triangulated: its registered partners within
  // registration_neighbour_window frames in capture order whose pose now disagrees with what
  // their nearest registered frames see (AgreementWithNeighbours) are deregistered, for the
  // growth to register again, checked against those frames. Such a pose came from few
  // correspondences, before the frames next to it were in the model (a frame of a weak
  // stretch reached from far). The gauge frames stay. Returns the frames deregistered.
  std::vector<image_t> UndoPosesAgainstNeighbours(image_t image_id, MapperReport* report);
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

 private:
  // (distance in capture order, other frame, pair) of the image's verified pairs with
  // registered frames within registration_neighbour_window frames of it, in pair order.
  std::vector<std::tuple<int, image_t, const MapperPair*>> RegisteredPartnersNear(
      image_t image_id) const;
  // The frame whose centre holds the scale in global bundles: the one farthest from gauge1_.
  image_t ScaleGaugeImage() const;
  // A whole-model bundle's cameras: constant, or refined as options_ ask (by the model's size).
  void SetIntrinsicsRefinement(BundleAdjustmentConfig* config,
                               BundleAdjustmentOptions* ba_options) const;
  // Priors holding self-calibrated or guessed focal lengths near their start
  // (focal_prior_sigma_log); sets the adjuster up.
  void AddFocalPriors(const BundleAdjustmentConfig& config, BundleAdjuster& adjuster);
  // The verified pairs of each frame.
  std::unordered_map<image_t, std::vector<const MapperPair*>> pairs_of_;
  image_t gauge1_ = kInvalidImageId, gauge2_ = kInvalidImageId;
};

}  // namespace loopsfm
