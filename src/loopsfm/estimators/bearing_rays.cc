#include "loopsfm/estimators/bearing_rays.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <ceres/loss_function.h>

namespace loopsfm {

double AngleBetween(const Eigen::Vector3d& direction, const Eigen::Vector3d& difference) {
  if (!(difference.squaredNorm() > 0.0)) return M_PI;
  return std::atan2(direction.cross(difference).norm(), direction.dot(difference));
}

std::optional<Eigen::Vector3d> IntersectRays(std::span<const BearingRay> rays) {
  if (rays.size() < 2) return std::nullopt;
  Eigen::Matrix3d lhs = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (const BearingRay& ray : rays) {
    // Projects onto the plane perpendicular to the ray: the offset from its line.
    const Eigen::Matrix3d across =
        Eigen::Matrix3d::Identity() - ray.direction * ray.direction.transpose();
    lhs += across;
    rhs += across * ray.origin;
  }
  if (!lhs.allFinite() || !rhs.allFinite()) return std::nullopt;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(lhs);
  if (!(eigen.eigenvalues()[0] > 1e-6 * eigen.eigenvalues()[2])) return std::nullopt;
  const Eigen::Vector3d point = lhs.ldlt().solve(rhs);
  if (!point.allFinite()) return std::nullopt;
  return point;
}

RayFit FitRays(const Eigen::Vector3d& point, std::span<const BearingRay> rays,
               const ceres::LossFunction* loss, double max_angle_rad) {
  RayFit fit;
  for (const BearingRay& ray : rays) {
    const double angle = AngleBetween(ray.direction, point - ray.origin);
    fit.num_inliers += angle <= max_angle_rad ? 1 : 0;
    const double sine = std::sin(std::min(angle, M_PI / 2));
    double rho[3] = {sine * sine, 1.0, 0.0};
    if (loss != nullptr) loss->Evaluate(sine * sine, rho);
    fit.cost += rho[0];
  }
  return fit;
}

std::optional<std::pair<Eigen::Vector3d, RayFit>> BestRayIntersection(
    std::span<const BearingRay> rays, const ceres::LossFunction* loss, double max_angle_rad) {
  constexpr size_t kMaxPairedRays = 8;
  std::optional<std::pair<Eigen::Vector3d, RayFit>> best;
  auto consider = [&](const std::optional<Eigen::Vector3d>& candidate) {
    if (!candidate) return;
    const RayFit fit = FitRays(*candidate, rays, loss, max_angle_rad);
    if (!best || fit.BetterThan(best->second)) best = std::make_pair(*candidate, fit);
  };
  consider(IntersectRays(rays));
  const size_t n = rays.size();
  const size_t m = std::min(n, kMaxPairedRays);
  for (size_t a = 0; a < m; ++a) {
    for (size_t b = a + 1; b < m; ++b) {
      const std::array<BearingRay, 2> pair = {rays[a * n / m], rays[b * n / m]};
      consider(IntersectRays(pair));
    }
  }
  return best;
}

}  // namespace loopsfm
