#pragma once
// Registration of an image against the map: its pose from 2D-3D correspondences (pixels of
// its keypoints and the 3D points of their tracks), for a camera with known intrinsics.
//
//   EstimateAbsolutePose: undistort with the camera model, P3P in LO-RANSAC with the pixel
//                         threshold converted to normalised coordinates, then (optionally)
//                         RefineAbsolutePose of the pose on the inliers.
//   RefineAbsolutePose:   Ceres non-linear least squares on the reprojection error in pixels,
//                         robust loss, optionally refining focal length / distortion.

#include <span>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"
#include "loopsfm/robust/loransac.h"
#include "loopsfm/scene/camera.h"

namespace loopsfm {

enum class RobustLossType {
  kTrivial,  // plain least squares
  kSoftL1,   // rho(s) = 2 (sqrt(1 + s) - 1): quadratic near zero, linear for large errors
  kCauchy,   // rho(s) = log(1 + s): gives outliers vanishing weight
};

struct AbsolutePoseRefinementOptions {
  // Robust loss applied to the squared reprojection error.
  RobustLossType loss_type = RobustLossType::kCauchy;
  // Scale of the robust loss in pixels: errors below it count (nearly) quadratically.
  double loss_scale_px = 1.0;
  // Maximum Levenberg-Marquardt iterations.
  int max_num_iterations = 100;
  // Stop when the largest gradient component falls below this (Ceres' gradient_tolerance).
  double gradient_tolerance = 1e-10;
  // Also refine the focal length(s). Needs many well-spread inliers; off by default.
  bool refine_focal_length = false;
  // Also refine the distortion parameters of the model (none for pinhole models).
  bool refine_extra_params = false;
  void Check() const;
};

struct AbsolutePoseRefinementReport {
  // True when Ceres returned a usable solution and the pose (and camera) were updated.
  bool success = false;
  // Correspondences used (the inliers).
  int num_residuals = 0;
  int num_iterations = 0;
  // Root mean square reprojection error over the used correspondences, in pixels.
  double initial_rmse_px = 0.0;
  double final_rmse_px = 0.0;
};

// Refines cam_from_world (and, if asked, the camera's focal length / extra parameters)
// on the correspondences whose inlier_mask entry is non-zero (all of them when the mask
// is empty). Needs at least 3 correspondences, and 6 when intrinsics are refined. On
// failure nothing is changed.
AbsolutePoseRefinementReport RefineAbsolutePose(const AbsolutePoseRefinementOptions& options,
                                                std::span<const char> inlier_mask,
                                                std::span<const Eigen::Vector2d> points2D,
                                                std::span<const Eigen::Vector3d> points3D_in_world,
                                                Rigid3d* cam_from_world, Camera* camera);

struct AbsolutePoseEstimationOptions {
  // Inlier threshold on the reprojection error, in pixels (COLMAP's mapper uses 12).
  double max_error_px = 12.0;
  // Fewest inliers for a successful estimate.
  int min_num_inliers = 6;
  // RANSAC settings; ransac.max_error is ignored and set from max_error_px.
  RansacOptions ransac;
  // Refine the RANSAC pose on its inliers with RefineAbsolutePose, then recount inliers.
  bool refine_pose = true;
  // Settings of that refinement; the intrinsics are never refined here (the camera is
  // const): call RefineAbsolutePose for that.
  AbsolutePoseRefinementOptions refinement;
  void Check() const;
};

struct AbsolutePoseReport {
  // True when a pose with at least min_num_inliers inliers was found.
  bool success = false;
  Rigid3d cam_from_world;
  // One entry per correspondence: 1 for inliers (reprojection error <= max_error_px).
  std::vector<char> inlier_mask;
  int num_inliers = 0;
  // RANSAC trials drawn.
  int num_trials = 0;
  // The pose refinement was asked for and failed (the solver gave no usable solution): the
  // RANSAC pose was kept.
  bool refinement_failed = false;
};

// points2D are pixels (COLMAP convention), points3D_in_world their 3D points; same size.
AbsolutePoseReport EstimateAbsolutePose(std::span<const Eigen::Vector2d> points2D,
                                        std::span<const Eigen::Vector3d> points3D_in_world,
                                        const Camera& camera,
                                        const AbsolutePoseEstimationOptions& options,
                                        Random& random);

}  // namespace loopsfm
