#include "loopsfm/robust/p3p.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

namespace loopsfm {
namespace internal {
namespace {

// Real roots of c2 x^2 + c1 x + c0 (or of the linear equation), cancellation-free.
int SolveQuadraticReal(double c2, double c1, double c0, double roots[2]) {
  const double scale = std::max({std::abs(c2), std::abs(c1), std::abs(c0)});
  if (scale == 0.0) return 0;
  if (std::abs(c2) <= 1e-14 * scale) {
    if (std::abs(c1) <= 1e-14 * scale) return 0;
    roots[0] = -c0 / c1;
    return 1;
  }
  const double discriminant = c1 * c1 - 4.0 * c2 * c0;
  if (discriminant < 0.0) return 0;
  const double q = -0.5 * (c1 + std::copysign(std::sqrt(discriminant), c1));
  if (q == 0.0) {  // c1 = c0 = 0: double root at zero
    roots[0] = 0.0;
    return 1;
  }
  roots[0] = q / c2;
  roots[1] = c0 / q;
  return 2;
}

}  // namespace

int SolveCubicReal(double c3, double c2, double c1, double c0, double roots[3]) {
  const double scale = std::max({std::abs(c2), std::abs(c1), std::abs(c0)});
  if (std::abs(c3) <= 1e-14 * scale || c3 == 0.0) return SolveQuadraticReal(c2, c1, c0, roots);
  // Monic x^3 + a x^2 + b x + c, depressed by x = t - a/3 to t^3 + p t + q.
  const double a = c2 / c3, b = c1 / c3, c = c0 / c3;
  const double shift = a / 3.0;
  const double p = b - a * shift;
  const double q = c - b * shift + 2.0 * shift * shift * shift;
  const double half_q = 0.5 * q, third_p = p / 3.0;
  const double discriminant = half_q * half_q + third_p * third_p * third_p;
  int num_roots = 0;
  if (discriminant > 0.0 || p >= 0.0) {
    // One real root (Cardano), summing terms of equal sign to avoid cancellation.
    const double u = std::cbrt(-half_q - std::copysign(std::sqrt(std::max(discriminant, 0.0)),
                                                       half_q));
    roots[0] = (u == 0.0 ? 0.0 : u - third_p / u) - shift;
    num_roots = 1;
  } else {
    // Three real roots (trigonometric form), p < 0.
    const double r = 2.0 * std::sqrt(-third_p);
    const double cos_arg = std::clamp(half_q / (third_p * std::sqrt(-third_p)), -1.0, 1.0);
    const double theta = std::acos(cos_arg) / 3.0;
    for (int k = 0; k < 3; ++k) roots[k] = r * std::cos(theta - 2.0 * M_PI * k / 3.0) - shift;
    num_roots = 3;
  }
  // Newton polishing on the monic polynomial; keep a step only if it lowers |f|.
  for (int k = 0; k < num_roots; ++k) {
    double x = roots[k];
    for (int iter = 0; iter < 3; ++iter) {
      const double f = ((x + a) * x + b) * x + c;
      const double df = (3.0 * x + 2.0 * a) * x + b;
      if (df == 0.0) break;
      const double candidate = x - f / df;
      const double f_candidate = ((candidate + a) * candidate + b) * candidate + c;
      if (!(std::abs(f_candidate) < std::abs(f))) break;
      x = candidate;
    }
    roots[k] = x;
  }
  return num_roots;
}

}  // namespace internal

namespace {

// Quadratic forms of the three distance equations: Lambda^T M_ij Lambda = a_ij.
struct DistanceEquations {
  Eigen::Matrix3d m12, m13, m23;
  double a12, a13, a23;

  Eigen::Vector3d Residuals(const Eigen::Vector3d& l) const {
    return {l.dot(m12 * l) - a12, l.dot(m13 * l) - a13, l.dot(m23 * l) - a23};
  }

  // Newton's method on the 3x3 system; each step must lower the residual.
  Eigen::Vector3d Refine(Eigen::Vector3d lambda) const {
    Eigen::Vector3d residual = Residuals(lambda);
    for (int iter = 0; iter < 5; ++iter) {
      Eigen::Matrix3d jacobian;
      jacobian.row(0) = 2.0 * (m12 * lambda).transpose();
      jacobian.row(1) = 2.0 * (m13 * lambda).transpose();
      jacobian.row(2) = 2.0 * (m23 * lambda).transpose();
      const Eigen::Vector3d step = jacobian.partialPivLu().solve(residual);
      if (!step.allFinite()) break;
      const Eigen::Vector3d candidate = lambda - step;
      const Eigen::Vector3d candidate_residual = Residuals(candidate);
      if (!(candidate_residual.squaredNorm() < residual.squaredNorm())) break;
      lambda = candidate;
      residual = candidate_residual;
      if (residual.squaredNorm() == 0.0) break;
    }
    return lambda;
  }
};

Eigen::Matrix3d PairForm(int i, int j, double cos_angle) {
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  m(i, i) = m(j, j) = 1.0;
  m(i, j) = m(j, i) = -cos_angle;
  return m;
}

double Det(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return a.dot(b.cross(c));
}

// Directions Lambda in the plane n^T Lambda = 0 with Lambda^T Q Lambda = 0 (up to sign).
int DirectionsInPlane(const Eigen::Vector3d& normal, const Eigen::Matrix3d& q,
                      Eigen::Vector3d directions[2]) {
  Eigen::Index axis;
  normal.cwiseAbs().minCoeff(&axis);
  const Eigen::Vector3d u = normal.cross(Eigen::Vector3d::Unit(axis)).normalized();
  const Eigen::Vector3d v = normal.cross(u).normalized();
  // (alpha u + beta v)^T Q (alpha u + beta v) = A alpha^2 + 2 B alpha beta + C beta^2.
  const double a = u.dot(q * u), b = u.dot(q * v), c = v.dot(q * v);
  const double scale = std::max({std::abs(a), std::abs(b), std::abs(c)});
  if (scale == 0.0) return 0;
  double discriminant = b * b - a * c;
  if (discriminant < 0.0) {
    if (discriminant < -1e-12 * scale * scale) return 0;
    discriminant = 0.0;  // a tangency lost to rounding
  }
  const double root = -b - std::copysign(std::sqrt(discriminant), b);
  int count = 0;
  if (std::abs(a) >= std::abs(c)) {
    // alpha / beta = root / a or c / root.
    directions[count++] = (root / a) * u + v;
    if (root != 0.0) directions[count++] = (c / root) * u + v;
  } else {
    // beta / alpha = root / c or a / root.
    directions[count++] = u + (root / c) * v;
    if (root != 0.0) directions[count++] = u + (a / root) * v;
  }
  return count;
}

// Right-handed orthonormal frame (columns) of a triangle: first axis along p1 - p2 (or
// p1 - p3), second axis the orthogonal part of the other edge.
Eigen::Matrix3d TriangleFrame(const Eigen::Vector3d& p1, const Eigen::Vector3d& p2,
                              const Eigen::Vector3d& p3, bool first_edge_12) {
  const Eigen::Vector3d first = first_edge_12 ? p1 - p2 : p1 - p3;
  const Eigen::Vector3d second = first_edge_12 ? p1 - p3 : p1 - p2;
  Eigen::Matrix3d frame;
  frame.col(0) = first.normalized();
  frame.col(1) = (second - frame.col(0).dot(second) * frame.col(0)).normalized();
  frame.col(2) = frame.col(0).cross(frame.col(1));
  return frame;
}

}  // namespace

std::vector<Rigid3d> SolveP3P(const std::array<Eigen::Vector3d, 3>& bearings,
                              const std::array<Eigen::Vector3d, 3>& points3D_in_world) {
  std::vector<Rigid3d> solutions;
  std::array<Eigen::Vector3d, 3> y;
  for (int i = 0; i < 3; ++i) {
    if (!bearings[i].allFinite() || !points3D_in_world[i].allFinite()) return solutions;
    const double norm = bearings[i].norm();
    if (!(norm > 0.0)) return solutions;
    y[i] = bearings[i] / norm;
  }
  const std::array<Eigen::Vector3d, 3>& x = points3D_in_world;

  // World triangle: edges and squared lengths; reject collinear points.
  const Eigen::Vector3d d12 = x[0] - x[1], d13 = x[0] - x[2];
  DistanceEquations eq;
  eq.a12 = d12.squaredNorm();
  eq.a13 = d13.squaredNorm();
  eq.a23 = (x[1] - x[2]).squaredNorm();
  const Eigen::Vector3d normal_world = d12.cross(d13);
  if (!(normal_world.squaredNorm() > 1e-20 * eq.a12 * eq.a13)) return solutions;

  const double b12 = y[0].dot(y[1]), b13 = y[0].dot(y[2]), b23 = y[1].dot(y[2]);
  if (std::max({b12, b13, b23}) >= 1.0 - 1e-15) return solutions;  // coincident rays
  eq.m12 = PairForm(0, 1, b12);
  eq.m13 = PairForm(0, 2, b13);
  eq.m23 = PairForm(1, 2, b23);

  // Homogeneous combinations: Lambda^T D1 Lambda = Lambda^T D2 Lambda = 0, normalised so
  // that the pencil coefficients below are comparable.
  Eigen::Matrix3d d1 = eq.a23 * eq.m12 - eq.a12 * eq.m23;
  Eigen::Matrix3d d2 = eq.a23 * eq.m13 - eq.a13 * eq.m23;
  d1 /= d1.norm();
  d2 /= d2.norm();
  if (!d1.allFinite() || !d2.allFinite()) return solutions;

  // det(D1 + g D2) = c3 g^3 + c2 g^2 + c1 g + c0, expanded column by column.
  const auto a1 = d1.col(0), a2 = d1.col(1), a3 = d1.col(2);
  const auto e1 = d2.col(0), e2 = d2.col(1), e3 = d2.col(2);
  const double c0 = Det(a1, a2, a3);
  const double c1 = Det(e1, a2, a3) + Det(a1, e2, a3) + Det(a1, a2, e3);
  const double c2 = Det(a1, e2, e3) + Det(e1, a2, e3) + Det(e1, e2, a3);
  const double c3 = Det(e1, e2, e3);

  // Degenerate pencil members p D1 + q D2, with (p, q) on the unit circle. Solve in g or
  // in 1/g, whichever keeps the leading coefficient large.
  double roots[3];
  const bool in_g = std::abs(c3) >= std::abs(c0);
  const int num_roots = in_g ? internal::SolveCubicReal(c3, c2, c1, c0, roots)
                             : internal::SolveCubicReal(c0, c1, c2, c3, roots);

  // Pick the member that is the best conditioned pair of real planes: two non-zero
  // eigenvalues of opposite sign, as close in magnitude as possible.
  struct Member {
    double p = 0, q = 0, quality = -1;
    Eigen::Vector3d normals[2];
  };
  Member best;
  std::vector<Eigen::Vector3d> null_vectors;
  for (int k = 0; k < num_roots; ++k) {
    double p = in_g ? 1.0 : roots[k], q = in_g ? roots[k] : 1.0;
    const double norm = std::hypot(p, q);
    p /= norm;
    q /= norm;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(p * d1 + q * d2);
    if (eigen.info() != Eigen::Success) continue;
    const Eigen::Vector3d values = eigen.eigenvalues();
    Eigen::Index zero;
    values.cwiseAbs().minCoeff(&zero);
    const int i = zero == 0 ? 1 : 0, j = zero == 2 ? 1 : 2;
    null_vectors.push_back(eigen.eigenvectors().col(zero));
    if (!(values(i) * values(j) < 0.0)) continue;
    const double quality = std::min(std::abs(values(i)), std::abs(values(j))) /
                           std::max(std::abs(values(i)), std::abs(values(j)));
    if (quality <= best.quality) continue;
    best = Member{p, q, quality, {}};
    // values(i) < 0 < values(j): sqrt(-s_i) (e_i . L) = +-sqrt(s_j) (e_j . L).
    const Eigen::Vector3d ei = std::sqrt(-values(i)) * eigen.eigenvectors().col(i);
    const Eigen::Vector3d ej = std::sqrt(values(j)) * eigen.eigenvectors().col(j);
    best.normals[0] = ei - ej;
    best.normals[1] = ei + ej;
  }

  // Candidate directions of Lambda: on the planes of the best member (with a second
  // conic of the pencil, as far from the member as possible), or, when no member splits
  // into real planes (tangent configurations), the null vectors themselves.
  std::vector<Eigen::Vector3d> directions;
  if (best.quality > 0.0) {
    const Eigen::Matrix3d other = -best.q * d1 + best.p * d2;
    for (const Eigen::Vector3d& normal : best.normals) {
      Eigen::Vector3d found[2];
      const int count = DirectionsInPlane(normal.normalized(), other, found);
      directions.insert(directions.end(), found, found + count);
    }
  } else {
    directions = null_vectors;
  }

  // Scale from the sum of the three equations (its form is positive definite), sign from
  // positive depths, then Newton polishing and verification.
  const Eigen::Matrix3d sum_form = eq.m12 + eq.m13 + eq.m23;
  const double sum_a = eq.a12 + eq.a13 + eq.a23;
  // Orthonormal frame of the world triangle: the longer of the two edges from point 1,
  // then the orthogonal part of the other edge. The camera triangle gets the same construction.
  const bool edge12_longer = eq.a12 >= eq.a13;
  const Eigen::Matrix3d world_frame = TriangleFrame(x[0], x[1], x[2], edge12_longer);
  const Eigen::Vector3d world_centroid = (x[0] + x[1] + x[2]) / 3.0;
  std::vector<Eigen::Vector3d> accepted;
  for (const Eigen::Vector3d& direction : directions) {
    const double form = direction.dot(sum_form * direction);
    if (!(form > 0.0)) continue;
    Eigen::Vector3d lambda = std::sqrt(sum_a / form) * direction;
    if (lambda.sum() < 0.0) lambda = -lambda;
    if (!(lambda.minCoeff() > 0.0)) continue;
    lambda = eq.Refine(lambda);
    if (!lambda.allFinite() || !(lambda.minCoeff() > 0.0)) continue;
    if (!(eq.Residuals(lambda).cwiseAbs().maxCoeff() <= 1e-6 * sum_a)) continue;
    const bool duplicate = std::any_of(accepted.begin(), accepted.end(), [&](const auto& other) {
      return (other - lambda).norm() <= 1e-9 * lambda.norm();
    });
    if (duplicate) continue;

    // The camera-frame triangle is congruent to the world one: R maps the world frame
    // onto the camera frame (an exact rotation even for nearly collinear points).
    const Eigen::Vector3d p1 = lambda(0) * y[0], p2 = lambda(1) * y[1], p3 = lambda(2) * y[2];
    const Eigen::Matrix3d rotation =
        TriangleFrame(p1, p2, p3, edge12_longer) * world_frame.transpose();
    Rigid3d cam_from_world;
    cam_from_world.rotation = Eigen::Quaterniond(rotation).normalized();
    cam_from_world.translation = (p1 + p2 + p3) / 3.0 - cam_from_world.rotation * world_centroid;
    if (!cam_from_world.rotation.coeffs().allFinite() ||
        !cam_from_world.translation.allFinite()) {
      continue;
    }
    accepted.push_back(lambda);
    solutions.push_back(cam_from_world);
    if (solutions.size() == 4) break;
  }
  return solutions;
}

}  // namespace loopsfm
