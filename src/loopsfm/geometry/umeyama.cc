#include "loopsfm/geometry/umeyama.h"

#include <cmath>

#include <Eigen/SVD>

namespace loopsfm {
namespace {

// Relative size of the second singular value of the cross-covariance below which the
// point sets count as collinear (the rotation about the line is then undetermined).
constexpr double kRankTolerance = 1e-10;

// Shared Umeyama solution. Returns false on degenerate input.
bool Umeyama(std::span<const Eigen::Vector3d> src, std::span<const Eigen::Vector3d> dst,
             bool estimate_scale, double* scale, Eigen::Matrix3d* rotation,
             Eigen::Vector3d* translation) {
  const size_t n = src.size();
  if (n != dst.size() || n < 3) return false;
  Eigen::Vector3d mean_src = Eigen::Vector3d::Zero(), mean_dst = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    mean_src += src[i];
    mean_dst += dst[i];
  }
  mean_src /= static_cast<double>(n);
  mean_dst /= static_cast<double>(n);

  // Cross-covariance (1/n) sum (dst_i - mean_dst)(src_i - mean_src)^T and src variance.
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  double variance_src = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d s = src[i] - mean_src;
    covariance += (dst[i] - mean_dst) * s.transpose();
    variance_src += s.squaredNorm();
  }
  covariance /= static_cast<double>(n);
  variance_src /= static_cast<double>(n);
  if (!covariance.allFinite() || !(variance_src > 0.0)) return false;

  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance,
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d singular = svd.singularValues();
  if (!(singular(1) > kRankTolerance * singular(0))) return false;

  // Flip the smallest axis when U V^T is a reflection, so the result is a rotation.
  Eigen::Vector3d sign = Eigen::Vector3d::Ones();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) sign(2) = -1.0;
  *rotation = svd.matrixU() * sign.asDiagonal() * svd.matrixV().transpose();
  *scale = estimate_scale ? singular.dot(sign) / variance_src : 1.0;
  if (!(*scale > 0.0) || !std::isfinite(*scale)) return false;
  *translation = mean_dst - *scale * (*rotation * mean_src);
  return translation->allFinite();
}

}  // namespace

std::optional<Sim3d> EstimateSim3(std::span<const Eigen::Vector3d> src,
                                  std::span<const Eigen::Vector3d> dst) {
  double scale;
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  if (!Umeyama(src, dst, /*estimate_scale=*/true, &scale, &rotation, &translation)) {
    return std::nullopt;
  }
  Sim3d dst_from_src;
  dst_from_src.scale = scale;
  dst_from_src.rotation = Eigen::Quaterniond(rotation).normalized();
  dst_from_src.translation = translation;
  return dst_from_src;
}

std::optional<Rigid3d> EstimateRigid3(std::span<const Eigen::Vector3d> src,
                                      std::span<const Eigen::Vector3d> dst) {
  double scale;
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  if (!Umeyama(src, dst, /*estimate_scale=*/false, &scale, &rotation, &translation)) {
    return std::nullopt;
  }
  return Rigid3d(Eigen::Quaterniond(rotation).normalized(), translation);
}

}  // namespace loopsfm
