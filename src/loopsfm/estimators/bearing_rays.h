#pragma once
// Points seen along bearing rays (a camera centre and a unit direction, both in the world
// frame): the least-squares intersection of rays, and how well a point explains them,
// scored by angle. Global positioning uses them to move points out of the flat parts of its
// cost; the cost here is that of its residual at the best scale, rho(sin^2(angle)) up to
// 90 degrees and rho(1) beyond. Unlike geometry/triangulation.h, nothing assumes a ray
// points into a camera's z > 0 half-space, so any bearing works (fisheye, outliers).
#include <optional>
#include <span>
#include <utility>

#include <Eigen/Core>

namespace ceres {
class LossFunction;
}  // namespace ceres

namespace loopsfm {

struct BearingRay {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  // Unit length.
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
};

// The angle in [0, pi] between a direction and a difference vector (pi for a zero
// difference).
double AngleBetween(const Eigen::Vector3d& direction, const Eigen::Vector3d& difference);

// The point nearest to all rays in the least-squares sense (distance to each ray's line);
// nullopt for fewer than two rays, nearly parallel rays or non-finite input.
std::optional<Eigen::Vector3d> IntersectRays(std::span<const BearingRay> rays);

// How well a point explains rays: how many it explains within the inlier angle, and the
// robust cost of all of them (loss nullptr: plain squares).
struct RayFit {
  int num_inliers = 0;
  double cost = 0.0;
  // More inliers, or as many at less cost.
  bool BetterThan(const RayFit& other) const {
    return num_inliers != other.num_inliers ? num_inliers > other.num_inliers
                                            : cost < other.cost;
  }
};

RayFit FitRays(const Eigen::Vector3d& point, std::span<const BearingRay> rays,
               const ceres::LossFunction* loss, double max_angle_rad);

// The intersection that fits the rays best (RayFit::BetterThan): of all of them or of a
// pair of them (pairs among at most 8 rays spread over the list), so a few outlier rays
// cannot spoil every candidate. nullopt where no rays intersect.
std::optional<std::pair<Eigen::Vector3d, RayFit>> BestRayIntersection(
    std::span<const BearingRay> rays, const ceres::LossFunction* loss, double max_angle_rad);

}  // namespace loopsfm
