#pragma once
// Triangulation of a 3D point from its observations in calibrated views.
//
// Every function works on normalised image coordinates (the z = 1 plane of the camera,
// i.e. Camera::CamFromImg of a pixel) and on cam_from_world 3x4 matrices [R | t], so it
// is independent of the camera model. Pixel thresholds are converted by the caller.

#include <optional>
#include <span>

#include <Eigen/Core>

namespace loopsfm {

using Matrix3x4d = Eigen::Matrix<double, 3, 4>;

// Two-view linear triangulation (DLT, smallest right singular vector of the 4x4 system).
// nullopt when the solution is at infinity (parallel rays) or not finite. Cheirality is
// not checked here.
std::optional<Eigen::Vector3d> TriangulatePoint(const Matrix3x4d& cam1_from_world,
                                                const Matrix3x4d& cam2_from_world,
                                                const Eigen::Vector2d& point1_normalized,
                                                const Eigen::Vector2d& point2_normalized);

// n-view linear triangulation: minimises sum_i |(I - f_i f_i^T) P_i X|^2 over homogeneous
// X, with f_i the unit ray of observation i (an algebraic error close to the angular
// one), then takes num_refinement_iterations Gauss-Newton steps on the sum of squared
// reprojection errors in normalised coordinates (a step is kept only if it lowers the
// cost). Needs at least 2 views; nullopt when degenerate.
std::optional<Eigen::Vector3d> TriangulateMultiView(
    std::span<const Matrix3x4d> cams_from_world,
    std::span<const Eigen::Vector2d> points_normalized, int num_refinement_iterations = 3);

// Angle in radians between the rays from two projection centres to a point, in [0, pi].
double CalculateTriangulationAngle(const Eigen::Vector3d& center1, const Eigen::Vector3d& center2,
                                   const Eigen::Vector3d& point3D_in_world);

// Whether some two of the rays (unit vectors from the projection centres to the point, in
// the world frame) are at least min_angle_rad apart: the test TriangulateMultiViewChecked
// makes of its widest pair, over every pair, stopping at the first wide enough (first and
// last rays first: in capture order those are usually the widest).
bool SomeRaysApart(std::span<const Eigen::Vector3d> rays, double min_angle_rad);

struct TriangulationOptions {
  // Gauss-Newton steps on the reprojection error after the linear solution (0 = DLT only).
  int num_refinement_iterations = 3;
  // Smallest acceptable triangulation angle (degrees), taken as the largest angle over
  // all pairs of views; below it the depth is too uncertain.
  double min_tri_angle_deg = 1.5;
  // Largest acceptable angular error (degrees) of the point in any view; the caller
  // converts a pixel threshold as atan(pixels / focal length).
  double max_angular_error_deg = 0.25;
  void Check() const;
};

enum class TriangulationStatus {
  kSuccess,
  kDegenerate,        // fewer than 2 views, or parallel rays / point at infinity
  kNegativeDepth,     // behind at least one camera
  kSmallAngle,        // triangulation angle below min_tri_angle_deg
  kLargeError,        // angular error above max_angular_error_deg in some view
};

struct TriangulationReport {
  TriangulationStatus status = TriangulationStatus::kDegenerate;
  Eigen::Vector3d point3D_in_world = Eigen::Vector3d::Zero();
  // Largest triangulation angle over pairs of views (degrees).
  double tri_angle_deg = 0.0;
  // Largest angular error over the views (degrees).
  double max_angular_error_deg = 0.0;
  bool success() const { return status == TriangulationStatus::kSuccess; }
};

// TriangulateMultiView followed by the filters of the options: cheirality in every view,
// triangulation angle, angular error. The point and the measured angles are filled in
// whenever the linear solution exists, so a caller can log why a point was rejected.
TriangulationReport TriangulateMultiViewChecked(std::span<const Matrix3x4d> cams_from_world,
                                                std::span<const Eigen::Vector2d> points_normalized,
                                                const TriangulationOptions& options);

}  // namespace loopsfm
