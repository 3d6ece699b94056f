#include "loopsfm/estimators/pose_manifold.h"

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "loopsfm/geometry/rigid3.h"

namespace loopsfm {
namespace {

using Matrix76 = Eigen::Matrix<double, 7, 6, Eigen::RowMajor>;
using Matrix67 = Eigen::Matrix<double, 6, 7, Eigen::RowMajor>;

Eigen::Quaterniond ExpRotation(const Eigen::Vector3d& rotation_vector) {
  const double angle = rotation_vector.norm();
  if (angle < 1e-12) {
    return Eigen::Quaterniond(1.0, 0.5 * rotation_vector.x(), 0.5 * rotation_vector.y(),
                              0.5 * rotation_vector.z())
        .normalized();
  }
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation_vector / angle));
}

Eigen::Vector3d LogRotation(Eigen::Quaterniond q) {
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // the shorter way round
  const double sin_half = q.vec().norm();
  if (sin_half < 1e-12) return 2.0 * q.vec();
  return 2.0 * std::atan2(sin_half, q.w()) * q.vec() / sin_half;
}

Matrix76 PlusJacobianAt(const double* x) {
  const Eigen::Map<const Eigen::Quaterniond> q(x);
  const Eigen::Map<const Eigen::Vector3d> t(x + 4);
  Matrix76 j = Matrix76::Zero();
  // d(Exp(d) * q)/dd at 0: vector part 0.5 (w I - [v]x), scalar part -0.5 v^T.
  j.block<3, 3>(0, 0) = 0.5 * (q.w() * Eigen::Matrix3d::Identity() - Skew(q.vec()));
  j.block<1, 3>(3, 0) = -0.5 * q.vec().transpose();
  // t = -R c: a turn Exp(d) gives Exp(d) t, so dt/dd = -[t]x; a centre step dc gives -R dc.
  j.block<3, 3>(4, 0) = -Skew(t);
  j.block<3, 3>(4, 3) = -q.toRotationMatrix();
  return j;
}

}  // namespace

bool PoseCentreManifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  const Eigen::Map<const Eigen::Quaterniond> q(x);
  const Eigen::Map<const Eigen::Vector3d> t(x + 4);
  const Eigen::Map<const Eigen::Vector3d> turn(delta);
  const Eigen::Map<const Eigen::Vector3d> move(delta + 3);
  const Eigen::Vector3d centre = -(q.conjugate() * t) + move;
  const Eigen::Quaterniond rotated = (ExpRotation(turn) * q).normalized();
  Eigen::Map<Eigen::Quaterniond> out_rotation(x_plus_delta);
  Eigen::Map<Eigen::Vector3d> out_translation(x_plus_delta + 4);
  out_rotation = rotated;
  out_translation = -(rotated * centre);
  return true;
}

bool PoseCentreManifold::PlusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Matrix76> out(jacobian);
  out = PlusJacobianAt(x);
  return true;
}

bool PoseCentreManifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  const Eigen::Map<const Eigen::Quaterniond> qy(y), qx(x);
  const Eigen::Map<const Eigen::Vector3d> ty(y + 4), tx(x + 4);
  Eigen::Map<Eigen::Vector3d> turn(y_minus_x), move(y_minus_x + 3);
  turn = LogRotation(qy * qx.conjugate());
  move = -(qy.conjugate() * ty) + (qx.conjugate() * tx);
  return true;
}

bool PoseCentreManifold::MinusJacobian(const double* x, double* jacobian) const {
  const Matrix76 plus = PlusJacobianAt(x);
  const Eigen::Matrix<double, 6, 6> normal = plus.transpose() * plus;
  Eigen::Map<Matrix67> out(jacobian);
  out = normal.ldlt().solve(plus.transpose());
  return true;
}

}  // namespace loopsfm
