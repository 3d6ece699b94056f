#include "loopsfm/matching/relative_pose_refinement.h"

#include <cmath>

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include "loopsfm/geometry/epipolar.h"
#include "loopsfm/geometry/rigid3.h"

namespace loopsfm {
namespace {

// Pose on the manifold: rotation update exp(w) R0, translation t0 + basis * d, renormalised.
struct LocalPose {
  Eigen::Matrix3d R0;
  Eigen::Vector3d t0;
  Eigen::Matrix<double, 3, 2> basis;

  LocalPose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) : R0(R), t0(t.normalized()) {
    // Two unit vectors orthogonal to t0.
    Eigen::Vector3d a = t0.unitOrthogonal();
    basis.col(0) = a;
    basis.col(1) = t0.cross(a);
  }
  void Apply(const Eigen::Matrix<double, 5, 1>& delta, Eigen::Matrix3d* R,
             Eigen::Vector3d* t) const {
    const Eigen::Vector3d w = delta.head<3>();
    const double angle = w.norm();
    const Eigen::Matrix3d dR =
        angle > 0 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix()
                  : Eigen::Matrix3d::Identity();
    *R = dR * R0;
    *t = (t0 + basis * delta.tail<2>()).normalized();
  }
};

}  // namespace

Eigen::Matrix3d EssentialFromPose(const Rigid3d& cam2_from_cam1) {
  return Skew(cam2_from_cam1.translation) * cam2_from_cam1.rotation.toRotationMatrix();
}

Rigid3d RefineRelativePose(const std::vector<Eigen::Vector2d>& points1,
                           const std::vector<Eigen::Vector2d>& points2, const Rigid3d& initial,
                           double loss_scale, int max_iterations) {
  Eigen::Matrix3d R = initial.rotation.toRotationMatrix();
  Eigen::Vector3d t = initial.translation.normalized();
  const size_t n = points1.size();
  if (n < 5 || !t.allFinite()) return initial;

  const double s2 = loss_scale * loss_scale;
  // Cauchy loss: rho(r^2) = s^2 log(1 + r^2 / s^2); IRLS weight rho' = 1 / (1 + r^2 / s^2).
  auto cost_of = [&](const Eigen::Matrix3d& Rc, const Eigen::Vector3d& tc) {
    const Eigen::Matrix3d E = Skew(tc) * Rc;
    double cost = 0;
    for (size_t i = 0; i < n; ++i) {
      const double r = SampsonResidual(E, points1[i], points2[i]);
      cost += s2 * std::log1p(r * r / s2);
    }
    return cost;
  };

  double cost = cost_of(R, t);
  double lambda = 1e-4;
  Eigen::VectorXd residuals(n);
  Eigen::Matrix<double, Eigen::Dynamic, 5> J(n, 5);
  for (int iter = 0; iter < max_iterations; ++iter) {
    const LocalPose local(R, t);
    const Eigen::Matrix3d E = Skew(local.t0) * local.R0;
    for (size_t i = 0; i < n; ++i) residuals[i] = SampsonResidual(E, points1[i], points2[i]);
    // Central differences: 10 evaluations of n cheap residuals.
    constexpr double kStep = 1e-6;
    for (int k = 0; k < 5; ++k) {
      Eigen::Matrix<double, 5, 1> delta = Eigen::Matrix<double, 5, 1>::Zero();
      Eigen::Matrix3d Rp, Rm;
      Eigen::Vector3d tp, tm;
      delta[k] = kStep;
      local.Apply(delta, &Rp, &tp);
      delta[k] = -kStep;
      local.Apply(delta, &Rm, &tm);
      const Eigen::Matrix3d Ep = Skew(tp) * Rp, Em = Skew(tm) * Rm;
      for (size_t i = 0; i < n; ++i) {
        J(i, k) = (SampsonResidual(Ep, points1[i], points2[i]) -
                   SampsonResidual(Em, points1[i], points2[i])) /
                  (2 * kStep);
      }
    }
    const Eigen::VectorXd weights =
        (1.0 + residuals.array().square() / s2).inverse().matrix();
    const Eigen::Matrix<double, 5, 5> JtJ = J.transpose() * weights.asDiagonal() * J;
    const Eigen::Matrix<double, 5, 1> Jtr = J.transpose() * weights.asDiagonal() * residuals;

    bool improved = false;
    for (int attempt = 0; attempt < 10 && !improved; ++attempt) {
      Eigen::Matrix<double, 5, 5> A = JtJ;
      A.diagonal() += lambda * (JtJ.diagonal().array() + 1e-12).matrix();
      const Eigen::Matrix<double, 5, 1> delta = A.ldlt().solve(-Jtr);
      Eigen::Matrix3d R_new;
      Eigen::Vector3d t_new;
      local.Apply(delta, &R_new, &t_new);
      const double new_cost = cost_of(R_new, t_new);
      if (std::isfinite(new_cost) && new_cost < cost) {
        const double relative_decrease = (cost - new_cost) / std::max(cost, 1e-300);
        R = R_new;
        t = t_new;
        cost = new_cost;
        lambda = std::max(lambda / 10, 1e-10);
        improved = true;
        if (relative_decrease < 1e-10 || delta.norm() < 1e-12) return Rigid3d(Eigen::Quaterniond(R).normalized(), t);
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
  }
  return Rigid3d(Eigen::Quaterniond(R).normalized(), t);
}

}  // namespace loopsfm
