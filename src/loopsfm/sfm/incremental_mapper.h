#pragma once
// Incremental Structure-from-Motion over tracks: a two-view start, then one frame at a time
// registered from 2D-3D correspondences (P3P in LO-RANSAC, pose refinement), tracks
// triangulated as soon as two registered frames see them, local bundle adjustment after
// each registration and global bundle adjustment (with re-triangulation and outlier
// filtering) whenever the model has grown by a set fraction. Frames that no model can take
// start a new model, so a scene that breaks apart gives several models.

#include <vector>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/mapper_input.h"

namespace loopsfm {

struct IncrementalMapperOptions {
  // Initial pair: fewest inlier matches.
  int init_min_num_inliers = 100;
  // Initial pair: largest fraction of its inliers a homography may explain (planar scenes
  // and pure rotations make poor starts).
  double init_max_h_inlier_ratio = 0.5;
  // Initial pair: smallest median triangulation angle, degrees.
  double init_min_tri_angle_deg = 3.0;
  // Registration: inlier threshold in pixels and fewest inliers / inlier ratio.
  double abs_pose_max_error_px = 8.0;
  int abs_pose_min_num_inliers = 30;
  double abs_pose_min_inlier_ratio = 0.25;
  // Tries to register one frame per model before giving up on it.
  int max_registration_trials = 2;
  // Triangulation and filtering: reprojection error in pixels, angle in degrees.
  double max_reproj_error_px = 4.0;
  double min_tri_angle_deg = 1.5;
  // Local bundle adjustment: the new frame and this many frames sharing most points with it.
  int local_ba_num_images = 6;
  // Global bundle adjustment when the registered frame count has grown by this fraction.
  double global_ba_growth = 0.25;
  // Refine focal lengths of cameras whose intrinsics were guessed (no prior focal length).
  bool refine_guessed_focal_length = true;
  // Refine distortion parameters too (OPENCV, SIMPLE_RADIAL, RADIAL cameras).
  bool refine_extra_params = false;
  // Stop after this many models; models smaller than min_model_size frames are discarded.
  int max_num_models = 10;
  int min_model_size = 3;
  // Worker threads for bundle adjustment (0: all cores).
  int num_threads = 0;
  uint64_t seed = kDefaultRandomSeed;
  void Check() const;
};

struct MapperReport {
  int num_models = 0;
  int num_registered = 0;
  int num_local_ba = 0;
  int num_global_ba = 0;
  double seconds_registration = 0.0;
  double seconds_triangulation = 0.0;
  double seconds_local_ba = 0.0;
  double seconds_global_ba = 0.0;
};

// Called after each registration with (registered in this model, frames in all).
using MapperProgress = std::function<void(size_t, size_t)>;

// Models sorted by size, largest first.
std::vector<Reconstruction> RunIncrementalMapper(const MapperInput& input,
                                                 const IncrementalMapperOptions& options,
                                                 MapperReport* report,
                                                 const MapperProgress& progress = {});

}  // namespace loopsfm
