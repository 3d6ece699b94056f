#include "loopsfm/robust/absolute_pose_estimator.h"

#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/robust/p3p.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Points at depths below this (relative to their distance) count as not in front.
bool InFront(const Eigen::Vector3d& point_in_cam) {
  return point_in_cam.z() > std::numeric_limits<double>::epsilon() * point_in_cam.norm();
}

// Sum of squared normalised reprojection errors; +inf when a point is not in front.
double PoseCost(std::span<const Eigen::Vector2d> points2D, std::span<const Eigen::Vector3d> points3D,
                std::span<const uint32_t> indices, const Rigid3d& cam_from_world) {
  double cost = 0.0;
  for (const uint32_t i : indices) {
    const Eigen::Vector3d p = cam_from_world * points3D[i];
    if (!InFront(p)) return std::numeric_limits<double>::infinity();
    cost += (p.head<2>() / p.z() - points2D[i]).squaredNorm();
  }
  return cost;
}

}  // namespace

P3PEstimator::P3PEstimator(std::span<const Eigen::Vector2d> points2D_normalized,
                           std::span<const Eigen::Vector3d> points3D_in_world)
    : points2D_(points2D_normalized), points3D_(points3D_in_world) {
  LOOPSFM_CHECK_EQ(points2D_.size(), points3D_.size());
}

std::vector<Rigid3d> P3PEstimator::Estimate(std::span<const uint32_t> sample) const {
  LOOPSFM_CHECK_EQ(sample.size(), static_cast<size_t>(kMinNumSamples));
  const std::array<Eigen::Vector3d, 3> bearings = {points2D_[sample[0]].homogeneous(),
                                                   points2D_[sample[1]].homogeneous(),
                                                   points2D_[sample[2]].homogeneous()};
  const std::array<Eigen::Vector3d, 3> points3D = {points3D_[sample[0]], points3D_[sample[1]],
                                                   points3D_[sample[2]]};
  return SolveP3P(bearings, points3D);
}

void P3PEstimator::Residuals(const Rigid3d& cam_from_world,
                             std::vector<double>* squared_residuals) const {
  squared_residuals->resize(points2D_.size());
  const Eigen::Matrix3d rotation = cam_from_world.rotation.toRotationMatrix();
  for (size_t i = 0; i < points2D_.size(); ++i) {
    const Eigen::Vector3d p = rotation * points3D_[i] + cam_from_world.translation;
    (*squared_residuals)[i] = InFront(p) ? (p.head<2>() / p.z() - points2D_[i]).squaredNorm()
                                         : std::numeric_limits<double>::max();
  }
}

bool P3PEstimator::EstimateNonMinimal(std::span<const uint32_t> inliers,
                                      Rigid3d* cam_from_world) const {
  return RefinePoseNormalized(points2D_, points3D_, inliers, cam_from_world);
}

bool RefinePoseNormalized(std::span<const Eigen::Vector2d> points2D_normalized,
                          std::span<const Eigen::Vector3d> points3D_in_world,
                          std::span<const uint32_t> indices, Rigid3d* cam_from_world,
                          int max_num_iterations) {
  LOOPSFM_CHECK_EQ(points2D_normalized.size(), points3D_in_world.size());
  if (indices.size() < 3) return false;
  Rigid3d pose = *cam_from_world;
  double cost = PoseCost(points2D_normalized, points3D_in_world, indices, pose);
  if (!std::isfinite(cost)) return false;
  double damping = 1e-4;
  bool converged = false;
  for (int iter = 0; iter < max_num_iterations && cost > 0.0 && !converged; ++iter) {
    // Left perturbation: cam_from_world <- (exp(omega) R, t + delta_t), so the point in
    // the camera moves by -[R X]_x omega + delta_t.
    Eigen::Matrix<double, 6, 6> hessian = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> gradient = Eigen::Matrix<double, 6, 1>::Zero();
    const Eigen::Matrix3d rotation = pose.rotation.toRotationMatrix();
    for (const uint32_t i : indices) {
      const Eigen::Vector3d rotated = rotation * points3D_in_world[i];
      const Eigen::Vector3d p = rotated + pose.translation;
      const double inv_z = 1.0 / p.z();
      const Eigen::Vector2d residual = p.head<2>() * inv_z - points2D_normalized[i];
      Eigen::Matrix<double, 2, 3> d_proj;
      d_proj << inv_z, 0.0, -p.x() * inv_z * inv_z, 0.0, inv_z, -p.y() * inv_z * inv_z;
      Eigen::Matrix<double, 2, 6> jacobian;
      jacobian.leftCols<3>() = -d_proj * Skew(rotated);
      jacobian.rightCols<3>() = d_proj;
      hessian += jacobian.transpose() * jacobian;
      gradient += jacobian.transpose() * residual;
    }
    // Try damped steps until one lowers the cost (or the damping becomes absurd).
    bool improved = false;
    while (!improved && damping < 1e8) {
      Eigen::Matrix<double, 6, 6> damped = hessian;
      damped.diagonal() += damping * hessian.diagonal().cwiseMax(1e-12);
      const Eigen::Matrix<double, 6, 1> step = -damped.ldlt().solve(gradient);
      if (!step.allFinite()) break;
      Rigid3d candidate = pose;
      const Eigen::Vector3d omega = step.head<3>();
      const double angle = omega.norm();
      if (angle > 0.0) {
        candidate.rotation =
            (Eigen::Quaterniond(Eigen::AngleAxisd(angle, omega / angle)) * pose.rotation)
                .normalized();
      }
      candidate.translation += step.tail<3>();
      const double candidate_cost =
          PoseCost(points2D_normalized, points3D_in_world, indices, candidate);
      if (candidate_cost < cost) {
        converged = candidate_cost > (1.0 - 1e-10) * cost || step.norm() < 1e-14;
        pose = candidate;
        cost = candidate_cost;
        damping = std::max(1e-8, damping * 0.1);
        improved = true;
      } else {
        damping *= 10.0;
      }
    }
    if (!improved) break;
  }
  *cam_from_world = pose;
  return true;
}

RansacReport<Rigid3d> EstimateAbsolutePoseNormalized(
    std::span<const Eigen::Vector2d> points2D_normalized,
    std::span<const Eigen::Vector3d> points3D_in_world, const RansacOptions& options,
    Random& random) {
  const P3PEstimator estimator(points2D_normalized, points3D_in_world);
  return LoRansac(estimator, options, random);
}

}  // namespace loopsfm
