#pragma once
// Global positioning for the global mapper (GLOMAP, Pan et al., ECCV 2024, "Global
// Structure-from-Motion Revisited"): with every camera's rotation known from rotation
// averaging, estimates all camera centres and all point positions at once from the bearing
// of each observation, starting from random positions.
//
// Unknowns: camera centres c_i, point positions X_p and one scale s_ip >= min_scale per
// observation. Each observation of point p by camera i has the residual
//
//   r_ip = v_ip - s_ip * (X_p - c_i),     v_ip = R_i^T * bearing_ip  (unit, world frame)
//
// with R_i the rotation of cam_from_world. The scale multiplies the position difference,
// not the observed direction, because this keeps each residual bounded: for given
// positions the best s_ip leaves |r_ip| = sin(angle between v_ip and X_p - c_i) when the
// angle is below 90 degrees, and |r_ip| = |v_ip| = 1 beyond it (s_ip at its lower bound).
// An observation, however wrong, so costs at most about 1, like an angular error, and
// outliers and the random start cannot dominate. The other form, s_ip * v_ip - (X_p - c_i),
// measures distances in world units (unbounded) and is minimised by collapsing every
// position onto one point.
//
// Optional camera-to-camera terms use the same residual with a relative translation
// direction in place of a bearing: v_ij - s_ij * (c_j - c_i) (GLOMAP's BATA form).
//
// Gauge: translation and global scale are free (rotation is fixed by the known rotations).
// Moving every position by a constant changes no residual; multiplying every position by k
// and every s by 1/k neither, so the directions do not fix the scale. As in GLOMAP, no
// camera is held constant during the solve (Levenberg-Marquardt's damping handles the
// four-dimensional null space, and a fixed camera slows convergence from a random start);
// the lower bound on the scales keeps the positions from growing without bound. After the
// solve, with normalize_gauge, the result is moved and scaled so the camera centres have
// zero mean and unit RMS distance from it (see the options).
//
// From a random start some points end in a flat part of the cost the solver cannot leave:
// behind a camera, where their residuals saturate, or far out along nearly parallel rays,
// where their pull fades with distance. After the solve each point is compared with the
// intersections of its rays from the estimated centres (bearing_rays.h); those that a ray
// intersection explains better move there, and the problem is solved once more.
//
//   GlobalPositioningInput input;
//   input.cam_from_world_rotations = rotations;              // from rotation averaging
//   input.observations.push_back({image_id, point_id, bearing_in_cam});
//   GlobalPositioningResult result = SolveGlobalPositioning(input, options);
//   auto poses = CamFromWorldFromCentres(input.cam_from_world_rotations,
//                                        result.camera_centres);
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"
#include "loopsfm/util/types.h"

namespace loopsfm {

enum class PositioningLoss {
  kTrivial,  // plain least squares
  kHuber,    // quadratic below the scale, linear above (GLOMAP's choice)
  kCauchy,   // log(1 + s): outliers get vanishing weight
};

enum class PositioningLinearSolver {
  kSparseSchur,     // scales eliminated, sparse Cholesky on the positions
  kIterativeSchur,  // scales eliminated, conjugate gradients on the positions (Schur-Jacobi)
};

struct GlobalPositioningOptions {
  // Robust loss on each residual. A residual's norm is about the sine of the angle between
  // the observed and the estimated direction, so loss_scale reads as sin(angle). Cauchy,
  // not GLOMAP's Huber: under Huber's linear tail the observations of wrong matches keep
  // pulling, and where few tracks tie two parts of a video together they can shrink one
  // part against the other. The scale sits in the middle of the range that mapped every
  // set (docs/global_mapper).
  PositioningLoss loss = PositioningLoss::kCauchy;
  double loss_scale = 0.05;
  // Cameras and points without an initial position are drawn uniformly from the cube
  // [-random_init_extent, random_init_extent]^3.
  double random_init_extent = 100.0;
  // Lower bound of each observation's scale s (>= 0; GLOMAP: 1e-5). A term's pull on the
  // positions is proportional to its scale, so a positive bound never switches one off
  // entirely, and it bounds how far the free global scale can grow.
  double min_scale = 1e-5;
  // Points seen by fewer observations are left out (a point seen once is only known along
  // a ray, and it does not constrain the cameras).
  int min_num_views_per_point = 2;
  // Weight of a camera-to-camera direction term relative to one point observation.
  double camera_direction_weight = 1.0;
  // The report counts observations whose final angle exceeds this (degrees).
  double max_angle_error_deg = 2.0;
  // After the solve, move each point to the best intersection of its rays from the
  // estimated centres (of all of them or of a pair, bearing_rays.h) where that explains
  // more of its observations within max_angle_error_deg, or as many at half the robust
  // cost, and solve once more. Such points were left by the random start where the cost is
  // flat: behind a camera (the residuals saturate) or far out along nearly parallel rays
  // (their pull fades).
  bool retriangulate_points = true;
  // After solving, move and scale the positions so the camera centres have zero mean and
  // unit RMS distance from it (a similarity: residual angles do not change). Off: the
  // result stays in the frame the solve ended in (initial positions' frame, roughly).
  bool normalize_gauge = true;
  // Iterative Schur solves each step faster, but its inexact steps can end elsewhere: from a
  // random start one synthetic scene in nine (docs/global_mapper).
  PositioningLinearSolver linear_solver = PositioningLinearSolver::kSparseSchur;
  // Levenberg-Marquardt iterations.
  int max_num_iterations = 100;
  // Stop when the relative cost decrease of a step falls below this (GLOMAP: 1e-5).
  double function_tolerance = 1e-5;
  // Stop once the camera centres have settled: two successful steps in a row that moved no
  // centre by more than this times the centres' spread (RMS distance from their mean).
  // Points caught far out along nearly parallel rays otherwise creep for dozens of steps
  // after the cameras have converged; retriangulate_points moves them in one go. 0: off.
  double settle_tolerance = 1e-4;
  // Threads for Ceres; <= 0: all hardware threads.
  int num_threads = -1;
  // Seed of the random initial positions.
  uint64_t seed = kDefaultRandomSeed;
  void Check() const;  // throws InvalidArgument
};

// Camera image_id sees point point_id along bearing_in_cam (camera frame; any non-zero
// length, normalised by the solver), computed by the caller from the keypoint through the
// camera model.
struct BearingObservation {
  image_t image_id = kInvalidImageId;
  point3D_t point_id = kInvalidPoint3DId;
  Eigen::Vector3d bearing_in_cam = Eigen::Vector3d::UnitZ();
};

// The direction of c2 - c1 in the world frame (any non-zero length), e.g. from a relative
// pose: -R_2^T * t_2_from_1.
struct CameraPairDirection {
  image_t image_id1 = kInvalidImageId;
  image_t image_id2 = kInvalidImageId;
  Eigen::Vector3d direction_in_world = Eigen::Vector3d::UnitX();
};

struct GlobalPositioningInput {
  // Known rotations of every camera that observations or directions name.
  std::map<image_t, Eigen::Quaterniond> cam_from_world_rotations;
  std::vector<BearingObservation> observations;
  // Optional camera-to-camera terms.
  std::vector<CameraPairDirection> camera_directions;
  // Optional starting positions; anything without one starts at a random position.
  std::map<image_t, Eigen::Vector3d> initial_centres;
  std::map<point3D_t, Eigen::Vector3d> initial_points;
};

struct GlobalPositioningReport {
  bool success = false;
  // Cameras and points that entered the problem.
  int num_cameras = 0;
  int num_points = 0;
  // Cameras of the input that no used observation or direction constrains (not positioned).
  int num_unconstrained_cameras = 0;
  // Points left out for having fewer than min_num_views_per_point observations.
  int num_skipped_points = 0;
  // Point observations and camera-to-camera terms that entered the problem.
  int num_observations = 0;
  int num_camera_directions = 0;
  // Used observations whose final angle exceeds max_angle_error_deg.
  int num_large_angle_observations = 0;
  // num_large_angle_observations as a fraction of num_observations (0 without any).
  double LargeAngleFraction() const {
    return num_observations > 0
               ? static_cast<double>(num_large_angle_observations) / num_observations
               : 0.0;
  }
  // Points moved by retriangulate_points (then solved once more).
  int num_retriangulated_points = 0;
  // Over both solves when points were moved; the initial cost is the first solve's.
  int num_iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double time_s = 0.0;
  std::string termination;
};

struct GlobalPositioningResult {
  // World-frame camera centres and point positions of what entered the problem.
  std::map<image_t, Eigen::Vector3d> camera_centres;
  std::map<point3D_t, Eigen::Vector3d> points;
  // Per input observation, in input order: the angle (radians) between the observed
  // world direction and X_p - c_i; NaN for observations of left-out points.
  std::vector<double> observation_angles;
  GlobalPositioningReport report;
};

// Solves the problem above. Throws InvalidArgument for bad options, for input with nothing
// to position (no observations and no directions), for an observation or direction that
// names a camera without a rotation, for an initial position of an unknown camera or point,
// and for zero or non-finite bearings, directions, rotations or positions. When no point
// has enough views and there are no directions, returns report.success = false and no
// positions. On solver failure, success is false and the positions are those reached.
GlobalPositioningResult SolveGlobalPositioning(const GlobalPositioningInput& input,
                                               const GlobalPositioningOptions& options = {});

// cam_from_world poses from rotations and centres (t = -R c), for the cameras that have a
// centre; each must have a rotation (LOOPSFM_CHECK).
std::map<image_t, Rigid3d> CamFromWorldFromCentres(
    const std::map<image_t, Eigen::Quaterniond>& cam_from_world_rotations,
    const std::map<image_t, Eigen::Vector3d>& camera_centres);

}  // namespace loopsfm
