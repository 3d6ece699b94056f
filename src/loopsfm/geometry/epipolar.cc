#include "loopsfm/geometry/epipolar.h"

#include <cmath>

#include <Eigen/Dense>

namespace loopsfm {
namespace {

// Similarity that moves the points' centroid to the origin and scales their mean distance
// from it to sqrt(2); false when the points all coincide.
bool NormalizingTransform(std::span<const Eigen::Vector2d> points, Eigen::Matrix3d* transform) {
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) centroid += p;
  centroid /= static_cast<double>(points.size());
  double mean_distance = 0.0;
  for (const Eigen::Vector2d& p : points) mean_distance += (p - centroid).norm();
  mean_distance /= static_cast<double>(points.size());
  if (!(mean_distance > 0.0)) return false;
  const double scale = std::sqrt(2.0) / mean_distance;
  *transform << scale, 0.0, -scale * centroid.x(), 0.0, scale, -scale * centroid.y(), 0.0, 0.0,
      1.0;
  return true;
}

}  // namespace

double SampsonResidual(const Eigen::Matrix3d& M, const Eigen::Vector2d& x1,
                       const Eigen::Vector2d& x2) {
  const Eigen::Vector3d h1 = x1.homogeneous(), h2 = x2.homogeneous();
  const Eigen::Vector3d Mx1 = M * h1;
  const Eigen::Vector3d Mtx2 = M.transpose() * h2;
  const double denominator = Mx1.head<2>().squaredNorm() + Mtx2.head<2>().squaredNorm();
  if (denominator <= 0) return 0.0;
  return h2.dot(Mx1) / std::sqrt(denominator);
}

double SampsonSquaredError(const Eigen::Matrix3d& M, const Eigen::Vector2d& x1,
                           const Eigen::Vector2d& x2) {
  const double r = SampsonResidual(M, x1, x2);
  return r * r;
}

Eigen::Matrix3d FundamentalFromEightPoints(std::span<const Eigen::Vector2d> points1,
                                           std::span<const Eigen::Vector2d> points2) {
  const Eigen::Matrix3d zero = Eigen::Matrix3d::Zero();
  if (points1.size() != points2.size() || points1.size() < 8) return zero;
  Eigen::Matrix3d T1, T2;
  if (!NormalizingTransform(points1, &T1) || !NormalizingTransform(points2, &T2)) return zero;

  // Normal equations of the rows kron(x2, x1) f = 0: the smallest eigenvector of A^T A.
  Eigen::Matrix<double, 9, 9> normal = Eigen::Matrix<double, 9, 9>::Zero();
  for (size_t i = 0; i < points1.size(); ++i) {
    const Eigen::Vector3d a = T1 * points1[i].homogeneous();
    const Eigen::Vector3d b = T2 * points2[i].homogeneous();
    Eigen::Matrix<double, 9, 1> row;
    row << b.x() * a, b.y() * a, b.z() * a;
    normal.selfadjointView<Eigen::Lower>().rankUpdate(row);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eigen(
      normal.selfadjointView<Eigen::Lower>());
  if (eigen.info() != Eigen::Success) return zero;
  // Undetermined (a second null direction): the points leave the solution free.
  const auto& values = eigen.eigenvalues();
  if (!(values(1) > 1e-12 * values(8))) return zero;
  const Eigen::Matrix<double, 9, 1> f = eigen.eigenvectors().col(0);
  Eigen::Matrix3d F;
  F << f(0), f(1), f(2), f(3), f(4), f(5), f(6), f(7), f(8);

  // Rank 2: the closest matrix in Frobenius norm.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d singular = svd.singularValues();
  singular(2) = 0.0;
  F = svd.matrixU() * singular.asDiagonal() * svd.matrixV().transpose();

  F = T2.transpose() * F * T1;  // back to the given coordinates
  const double norm = F.norm();
  return norm > 0.0 && F.allFinite() ? Eigen::Matrix3d(F / norm) : zero;
}

}  // namespace loopsfm
