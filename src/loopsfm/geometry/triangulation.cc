#include "loopsfm/geometry/triangulation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Dehomogenises a homogeneous 4-vector; nullopt at (or numerically at) infinity.
std::optional<Eigen::Vector3d> Dehomogenize(const Eigen::Vector4d& x) {
  const double w = x(3);
  if (!x.allFinite() || std::abs(w) <= 1e-14 * x.head<3>().norm() || w == 0.0) {
    return std::nullopt;
  }
  return x.head<3>() / w;
}

// Sum of squared reprojection errors in normalised coordinates; +inf when a point
// reaches the principal plane of a camera.
double ReprojectionCost(std::span<const Matrix3x4d> cams_from_world,
                        std::span<const Eigen::Vector2d> points, const Eigen::Vector3d& x) {
  double cost = 0.0;
  for (size_t i = 0; i < cams_from_world.size(); ++i) {
    const Eigen::Vector3d p = cams_from_world[i].leftCols<3>() * x + cams_from_world[i].col(3);
    if (std::abs(p.z()) < 1e-300) return std::numeric_limits<double>::infinity();
    cost += (p.head<2>() / p.z() - points[i]).squaredNorm();
  }
  return cost;
}

// Gauss-Newton on the reprojection error of one point; each step must lower the cost.
Eigen::Vector3d RefinePoint(std::span<const Matrix3x4d> cams_from_world,
                            std::span<const Eigen::Vector2d> points, Eigen::Vector3d x,
                            int num_iterations) {
  double cost = ReprojectionCost(cams_from_world, points, x);
  for (int iter = 0; iter < num_iterations && std::isfinite(cost); ++iter) {
    Eigen::Matrix3d hessian = Eigen::Matrix3d::Zero();
    Eigen::Vector3d gradient = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < cams_from_world.size(); ++i) {
      const Eigen::Matrix3d rotation = cams_from_world[i].leftCols<3>();
      const Eigen::Vector3d p = rotation * x + cams_from_world[i].col(3);
      const double inv_z = 1.0 / p.z();
      const Eigen::Vector2d residual = p.head<2>() * inv_z - points[i];
      Eigen::Matrix<double, 2, 3> d_proj;
      d_proj << inv_z, 0.0, -p.x() * inv_z * inv_z, 0.0, inv_z, -p.y() * inv_z * inv_z;
      const Eigen::Matrix<double, 2, 3> jacobian = d_proj * rotation;
      hessian += jacobian.transpose() * jacobian;
      gradient += jacobian.transpose() * residual;
    }
    const Eigen::Vector3d step = -hessian.ldlt().solve(gradient);
    if (!step.allFinite()) break;
    const Eigen::Vector3d candidate = x + step;
    const double candidate_cost = ReprojectionCost(cams_from_world, points, candidate);
    if (!(candidate_cost < cost)) break;
    x = candidate;
    const bool converged = step.norm() <= 1e-14 * (1.0 + x.norm());
    cost = candidate_cost;
    if (converged) break;
  }
  return x;
}

double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

constexpr double kRadToDeg = 180.0 / M_PI;

}  // namespace

std::optional<Eigen::Vector3d> TriangulatePoint(const Matrix3x4d& cam1_from_world,
                                                const Matrix3x4d& cam2_from_world,
                                                const Eigen::Vector2d& point1_normalized,
                                                const Eigen::Vector2d& point2_normalized) {
  Eigen::Matrix4d a;
  a.row(0) = point1_normalized.x() * cam1_from_world.row(2) - cam1_from_world.row(0);
  a.row(1) = point1_normalized.y() * cam1_from_world.row(2) - cam1_from_world.row(1);
  a.row(2) = point2_normalized.x() * cam2_from_world.row(2) - cam2_from_world.row(0);
  a.row(3) = point2_normalized.y() * cam2_from_world.row(2) - cam2_from_world.row(1);
  if (!a.allFinite()) return std::nullopt;
  const Eigen::JacobiSVD<Eigen::Matrix4d> svd(a, Eigen::ComputeFullV);
  return Dehomogenize(svd.matrixV().col(3));
}

std::optional<Eigen::Vector3d> TriangulateMultiView(
    std::span<const Matrix3x4d> cams_from_world,
    std::span<const Eigen::Vector2d> points_normalized, int num_refinement_iterations) {
  LOOPSFM_CHECK_EQ(cams_from_world.size(), points_normalized.size());
  if (cams_from_world.size() < 2) return std::nullopt;
  Eigen::Matrix4d normal_matrix = Eigen::Matrix4d::Zero();
  for (size_t i = 0; i < cams_from_world.size(); ++i) {
    const Eigen::Vector3d ray = points_normalized[i].homogeneous().normalized();
    // (I - f f^T) is a projector, so P^T (I - f f^T)^T (I - f f^T) P = P^T (I - f f^T) P.
    const Matrix3x4d residual_map =
        cams_from_world[i] - ray * (ray.transpose() * cams_from_world[i]);
    normal_matrix += cams_from_world[i].transpose() * residual_map;
  }
  if (!normal_matrix.allFinite()) return std::nullopt;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eigen(normal_matrix);
  if (eigen.info() != Eigen::Success) return std::nullopt;
  std::optional<Eigen::Vector3d> point = Dehomogenize(eigen.eigenvectors().col(0));
  if (!point || num_refinement_iterations <= 0) return point;
  return RefinePoint(cams_from_world, points_normalized, *point, num_refinement_iterations);
}

double CalculateTriangulationAngle(const Eigen::Vector3d& center1, const Eigen::Vector3d& center2,
                                   const Eigen::Vector3d& point3D_in_world) {
  return AngleBetween(point3D_in_world - center1, point3D_in_world - center2);
}

bool SomeRaysApart(std::span<const Eigen::Vector3d> rays, double min_angle_rad) {
  // The cosine decides where it is clearly on one side; atan2 where it is close.
  const double cos_min = std::cos(min_angle_rad);
  for (size_t i = 0; i < rays.size(); ++i) {
    for (size_t j = rays.size() - 1; j > i; --j) {
      const double cos_angle = rays[i].dot(rays[j]);
      if (cos_angle < cos_min - 1e-9) return true;
      if (cos_angle <= cos_min + 1e-9 && AngleBetween(rays[i], rays[j]) >= min_angle_rad) {
        return true;
      }
    }
  }
  return false;
}

void TriangulationOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(num_refinement_iterations >= 0,
                         "triangulation: num_refinement_iterations must be >= 0, got {}",
                         num_refinement_iterations);
  LOOPSFM_REQUIRE_OPTION(min_tri_angle_deg >= 0 && min_tri_angle_deg < 180,
                         "triangulation: min_tri_angle_deg must be in [0, 180), got {}",
                         min_tri_angle_deg);
  LOOPSFM_REQUIRE_OPTION(max_angular_error_deg > 0,
                         "triangulation: max_angular_error_deg must be positive, got {}",
                         max_angular_error_deg);
}

TriangulationReport TriangulateMultiViewChecked(std::span<const Matrix3x4d> cams_from_world,
                                                std::span<const Eigen::Vector2d> points_normalized,
                                                const TriangulationOptions& options) {
  TriangulationReport report;
  const std::optional<Eigen::Vector3d> point = TriangulateMultiView(
      cams_from_world, points_normalized, options.num_refinement_iterations);
  if (!point) return report;
  report.point3D_in_world = *point;

  // Rays from the projection centres to the point, and the errors of the observations.
  std::vector<Eigen::Vector3d> rays_in_world(cams_from_world.size());
  bool all_in_front = true;
  double max_error = 0.0;
  for (size_t i = 0; i < cams_from_world.size(); ++i) {
    const Eigen::Matrix3d rotation = cams_from_world[i].leftCols<3>();
    const Eigen::Vector3d point_in_cam = rotation * *point + cams_from_world[i].col(3);
    const Eigen::Vector3d center = -rotation.transpose() * cams_from_world[i].col(3);
    rays_in_world[i] = (*point - center).normalized();
    all_in_front &= point_in_cam.z() > 1e-12 * point_in_cam.norm();
    max_error = std::max(max_error,
                         AngleBetween(points_normalized[i].homogeneous(), point_in_cam));
  }
  // The widest pair has the smallest cosine; its angle is then taken with atan2, which
  // stays accurate for small angles.
  double min_cos = 2.0;
  size_t best_i = 0, best_j = 1;
  for (size_t i = 0; i < rays_in_world.size(); ++i) {
    for (size_t j = i + 1; j < rays_in_world.size(); ++j) {
      const double cos_angle = rays_in_world[i].dot(rays_in_world[j]);
      if (cos_angle < min_cos) {
        min_cos = cos_angle;
        best_i = i;
        best_j = j;
      }
    }
  }
  report.tri_angle_deg = AngleBetween(rays_in_world[best_i], rays_in_world[best_j]) * kRadToDeg;
  report.max_angular_error_deg = max_error * kRadToDeg;

  if (!all_in_front) {
    report.status = TriangulationStatus::kNegativeDepth;
  } else if (report.tri_angle_deg < options.min_tri_angle_deg) {
    report.status = TriangulationStatus::kSmallAngle;
  } else if (report.max_angular_error_deg > options.max_angular_error_deg) {
    report.status = TriangulationStatus::kLargeError;
  } else {
    report.status = TriangulationStatus::kSuccess;
  }
  return report;
}

}  // namespace loopsfm
