#include "loopsfm/synth/world.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace loopsfm {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Hits closer than this to the ray origin are ignored.
constexpr double kMinDistance = 1e-9;

struct Interval {
  double lo = -kInf;
  double hi = kInf;
  bool Empty() const { return !(lo < hi); }
};

Interval Intersect(const Interval& a, const Interval& b) {
  return {std::max(a.lo, b.lo), std::min(a.hi, b.hi)};
}

// Where the ray lies within horizontal distance r of the axis (an infinite vertical cylinder).
Interval InsideInfiniteCylinder(const Eigen::Vector2d& origin_from_axis,
                                const Eigen::Vector2d& direction_xy, double r) {
  const double a = direction_xy.squaredNorm();
  const double c = origin_from_axis.squaredNorm() - r * r;
  if (a < 1e-24) return c < 0.0 ? Interval{} : Interval{0.0, 0.0};
  const double half_b = origin_from_axis.dot(direction_xy);
  const double disc = half_b * half_b - a * c;
  if (disc <= 0.0) return {0.0, 0.0};
  const double s = std::sqrt(disc);
  return {(-half_b - s) / a, (-half_b + s) / a};
}

// Where the ray lies within bottom <= z <= top.
Interval InsideSlab(double origin_z, double direction_z, double bottom, double top) {
  if (std::abs(direction_z) < 1e-24) {
    return (origin_z >= bottom && origin_z <= top) ? Interval{} : Interval{0.0, 0.0};
  }
  double t0 = (bottom - origin_z) / direction_z;
  double t1 = (top - origin_z) / direction_z;
  if (t0 > t1) std::swap(t0, t1);
  return {t0, t1};
}

// The implicit function of the displaced cylinder at p, horizontal distance from the axis
// minus the displaced radius in that direction (positive outside), and its gradient.
double CylinderFunction(const BumpyCylinder& cylinder, const Eigen::Vector3d& p,
                        Eigen::Vector3d* gradient) {
  const Eigen::Vector2d radial = p.head<2>() - cylinder.axis_xy;
  const double rho = std::max(radial.norm(), 1e-12);
  const Eigen::Vector2d e_rho = radial / rho;
  const Eigen::Vector2d e_theta(-e_rho.y(), e_rho.x());
  Eigen::Vector2d dr;  // d radius / d theta, d radius / d z
  const double r = cylinder.RadiusAt(e_rho, p.z(), &dr);
  const Eigen::Vector2d horizontal = e_rho - (dr.x() / rho) * e_theta;
  *gradient = Eigen::Vector3d(horizontal.x(), horizontal.y(), -dr.y());
  return rho - r;
}

// Root of f in the bracket [lo, hi] (f(lo) and f(hi) of opposite signs) by Newton steps that
// fall back to bisection when they would leave the bracket.
template <typename F>
double RefineRoot(F&& f, double lo, double f_lo, double hi, double f_hi) {
  double t = lo - f_lo * (hi - lo) / (f_hi - f_lo);
  for (int iter = 0; iter < 60; ++iter) {
    double slope = 0.0;
    const double ft = f(t, &slope);
    if (ft == 0.0) break;
    if ((ft > 0.0) == (f_lo > 0.0)) {
      lo = t;
      f_lo = ft;
    } else {
      hi = t;
    }
    double next = slope != 0.0 ? t - ft / slope : lo;
    if (!(next > std::min(lo, hi) && next < std::max(lo, hi))) next = 0.5 * (lo + hi);
    const bool converged = std::abs(next - t) < 1e-12;
    t = next;
    if (converged) break;
  }
  return t;
}

std::optional<SurfaceHit> CastCylinder(const BumpyCylinder& cylinder, const Eigen::Vector3d& o,
                                       const Eigen::Vector3d& d, double max_distance) {
  const Eigen::Vector2d o_xy = o.head<2>() - cylinder.axis_xy;
  const Eigen::Vector2d d_xy = d.head<2>();
  const double amplitude = cylinder.bump_amplitude;
  Interval range =
      Intersect(InsideInfiniteCylinder(o_xy, d_xy, cylinder.radius + amplitude),
                InsideSlab(o.z(), d.z(), cylinder.bottom, cylinder.top));
  range = Intersect(range, {kMinDistance, max_distance});
  if (range.Empty()) return std::nullopt;
  // The surface lies in the shell between radius - amplitude and radius + amplitude.
  const Interval inner = InsideInfiniteCylinder(o_xy, d_xy, cylinder.radius - amplitude);
  Interval pieces[2] = {range, {0.0, 0.0}};
  if (!inner.Empty()) {
    pieces[0] = Intersect(range, {-kInf, inner.lo});
    pieces[1] = Intersect(range, {inner.hi, kInf});
  }
  Eigen::Vector3d gradient;
  // The function along the ray and its derivative by t.
  auto f = [&](double t, double* slope) {
    const double value = CylinderFunction(cylinder, o + t * d, &gradient);
    *slope = gradient.dot(d);
    return value;
  };
  // Sphere tracing: f changes by at most `lipschitz` per metre along any ray, so a step of
  // |f| / lipschitz cannot cross the surface. Where f falls towards zero the step may go up to
  // 25% (at most kMaxOvershoot) past the linear prediction of the crossing, to bracket it
  // quickly; a minimum step keeps grazing rays moving. So two crossings closer than
  // kMaxOvershoot along a ray (a bump seen at grazing angle) may be missed. The first sign
  // change is refined by Newton steps.
  constexpr double kMaxOvershoot = 0.01;
  const double lipschitz = cylinder.GradientBound();
  const double min_step = 2e-4 * cylinder.radius;
  for (const Interval& piece : pieces) {
    if (piece.Empty()) continue;
    double slope;
    double t_prev = piece.lo;
    double f_prev = f(t_prev, &slope);
    std::optional<double> root;
    if (f_prev == 0.0) root = t_prev;
    while (!root && t_prev < piece.hi) {
      const double safe = std::max(std::abs(f_prev) / lipschitz, min_step);
      double step = safe;
      if (slope * f_prev < 0.0) {
        step = std::max(safe, std::min(-1.25 * f_prev / slope, safe + kMaxOvershoot));
      }
      const double t = std::min(t_prev + step, piece.hi);
      const double ft = f(t, &slope);
      if (ft == 0.0 || (ft > 0.0) != (f_prev > 0.0)) {
        root = ft == 0.0 ? t : RefineRoot(f, t_prev, f_prev, t, ft);
      }
      t_prev = t;
      f_prev = ft;
    }
    if (!root) continue;
    SurfaceHit hit;
    hit.distance = *root;
    hit.point_in_world = o + *root * d;
    hit.kind = SurfaceKind::kCylinder;
    hit.material = cylinder.material;
    // `gradient` is from the last evaluation, within 1e-12 m of the root.
    const Eigen::Vector3d normal = gradient.normalized();
    hit.normal = normal.dot(d) > 0.0 ? -normal : normal;
    return hit;
  }
  return std::nullopt;
}

std::optional<SurfaceHit> CastBox(const TexturedBox& box, const Eigen::Vector3d& o,
                                  const Eigen::Vector3d& d, double max_distance) {
  double t_enter = -kInf, t_exit = kInf;
  int enter_axis = -1;
  for (int axis = 0; axis < 3; ++axis) {
    if (std::abs(d[axis]) < 1e-24) {
      if (o[axis] < box.min[axis] || o[axis] > box.max[axis]) return std::nullopt;
      continue;
    }
    double t0 = (box.min[axis] - o[axis]) / d[axis];
    double t1 = (box.max[axis] - o[axis]) / d[axis];
    if (t0 > t1) std::swap(t0, t1);
    if (t0 > t_enter) {
      t_enter = t0;
      enter_axis = axis;
    }
    t_exit = std::min(t_exit, t1);
  }
  // Rays starting inside a box see nothing of it (boxes are solid buildings).
  if (enter_axis < 0 || t_enter > t_exit || t_enter < kMinDistance || t_enter > max_distance) {
    return std::nullopt;
  }
  SurfaceHit hit;
  hit.distance = t_enter;
  hit.point_in_world = o + t_enter * d;
  hit.normal = Eigen::Vector3d::Zero();
  hit.normal[enter_axis] = d[enter_axis] > 0.0 ? -1.0 : 1.0;
  hit.kind = SurfaceKind::kBox;
  hit.material = box.material;
  hit.texture_origin = box.texture_origin;
  return hit;
}

}  // namespace

Eigen::Vector3d Material::Albedo(const Eigen::Vector3d& point_in_world, double footprint) const {
  const double value = FractalNoise(GradientNoise(seed), point_in_world, noise, footprint);
  const double s = 0.5 + 0.5 * std::tanh(contrast * value);
  // A coarse second noise varies the tint, so that large areas are not uniform.
  const FractalNoiseParams tint_params{noise.frequency * 0.2, 1, 0.5};
  const double tint = FractalNoise(GradientNoise(seed + 1), point_in_world, tint_params, footprint);
  const Eigen::Vector3d albedo = (dark + s * (light - dark)) * (1.0 + 0.5 * tint);
  return albedo.cwiseMax(0.0).cwiseMin(1.0);
}

double BumpyCylinder::GradientBound() const {
  // |grad n| <= 3.5 for one octave of GradientNoise (3.22 seen in 5e6 samples), so the
  // displacement field m = (n(q) + n(2q) / 2) / 1.6 has |grad_q m| <= 4.4; its derivatives by
  // arc length around the axis (at radius >= radius - bump_amplitude) and by z are bounded by
  // k below, and |grad f| <= sqrt(1 + 2 k^2).
  const double k = bump_amplitude * bump_frequency * 4.4 * radius / (radius - bump_amplitude);
  return std::sqrt(1.0 + 2.0 * k * k);
}

double BumpyCylinder::RadiusAt(const Eigen::Vector2d& dir_xy, double z,
                               Eigen::Vector2d* derivatives) const {
  const GradientNoise bumps(bump_seed);
  // Two octaves of noise on the undisplaced surface (periodic around the axis). Dividing by
  // 1.6 keeps the sum within [-1, 1], so the surface stays inside radius +- bump_amplitude.
  const Eigen::Vector3d q(radius * dir_xy.x() * bump_frequency,
                          radius * dir_xy.y() * bump_frequency, z * bump_frequency);
  Eigen::Vector3d g1, g2;
  const double n1 = bumps.Evaluate(q, &g1);
  const double n2 = bumps.Evaluate(2.0 * q + Eigen::Vector3d(3.7, 1.3, -2.9), &g2);
  if (derivatives) {
    // Gradient by q; q moves by radius * bump_frequency per radian along e_theta and by
    // bump_frequency per metre along z.
    const Eigen::Vector3d dm_dq = (g1 + g2) / 1.6;
    const Eigen::Vector2d e_theta(-dir_xy.y(), dir_xy.x());
    *derivatives = bump_amplitude * bump_frequency *
                   Eigen::Vector2d(radius * e_theta.dot(dm_dq.head<2>()), dm_dq.z());
  }
  return radius + bump_amplitude * (n1 + 0.5 * n2) / 1.6;
}

std::optional<SurfaceHit> SyntheticWorld::CastRay(const Eigen::Vector3d& origin,
                                                  const Eigen::Vector3d& direction,
                                                  double max_distance) const {
  std::optional<SurfaceHit> best;
  auto consider = [&](std::optional<SurfaceHit> hit, int index) {
    if (hit && hit->distance <= max_distance) {
      hit->index = index;
      max_distance = hit->distance;
      best = hit;
    }
  };
  if (ground && std::abs(direction.z()) > 1e-24) {
    const double t = (ground->height - origin.z()) / direction.z();
    if (t > kMinDistance && t <= max_distance) {
      SurfaceHit hit;
      hit.distance = t;
      hit.point_in_world = origin + t * direction;
      hit.point_in_world.z() = ground->height;
      hit.normal = Eigen::Vector3d(0.0, 0.0, direction.z() < 0.0 ? 1.0 : -1.0);
      hit.kind = SurfaceKind::kGround;
      hit.material = ground->material;
      consider(hit, 0);
    }
  }
  for (size_t i = 0; i < boxes.size(); ++i) {
    consider(CastBox(boxes[i], origin, direction, max_distance), static_cast<int>(i));
  }
  for (size_t i = 0; i < cylinders.size(); ++i) {
    consider(CastCylinder(cylinders[i], origin, direction, max_distance), static_cast<int>(i));
  }
  return best;
}

Eigen::Vector3d SyntheticWorld::Sky(const Eigen::Vector3d& direction) const {
  const double up = std::clamp(direction.z(), 0.0, 1.0);
  const Eigen::Vector3d horizon(0.80, 0.85, 0.92);
  const Eigen::Vector3d zenith(0.35, 0.55, 0.85);
  return horizon + std::sqrt(up) * (zenith - horizon);
}

Eigen::Vector3d SyntheticWorld::Shade(const std::optional<SurfaceHit>& hit,
                                      const Eigen::Vector3d& direction,
                                      double pixel_angle) const {
  if (!hit) return Sky(direction);
  // Size of one pixel on the surface along its longer axis; grazing views stretch it (up to
  // 20 times, so that the horizon keeps a little texture).
  const double cos_incidence = std::max(std::abs(hit->normal.dot(direction)), 0.05);
  const double footprint = hit->distance * pixel_angle / cos_incidence;
  const Eigen::Vector3d albedo = materials[hit->material].Albedo(hit->point_in_world - hit->texture_origin, footprint);
  // Lambertian with a soft fill: surfaces facing away from the light keep some contrast.
  const double lighting = 0.55 + 0.45 * hit->normal.dot(light_direction);
  return albedo * lighting;
}

}  // namespace loopsfm
