#pragma once
// Epipolar geometry of two views: the Sampson distance of a correspondence to a fundamental
// or essential matrix, and the normalised eight-point algorithm.

#include <span>

#include <Eigen/Core>

namespace loopsfm {

// Signed Sampson residual of a correspondence to M (x2^T M x1 = 0): a fundamental matrix with
// pixel coordinates, or an essential matrix with normalised ones (z = 1). Its square is the
// Sampson distance, a first-order approximation of the squared distance to the nearest
// correspondence that satisfies the constraint exactly, in the units of the coordinates.
// 0 where M maps both points to the epipoles (the distance is undefined there).
double SampsonResidual(const Eigen::Matrix3d& M, const Eigen::Vector2d& x1,
                       const Eigen::Vector2d& x2);

// The square of SampsonResidual.
double SampsonSquaredError(const Eigen::Matrix3d& M, const Eigen::Vector2d& x1,
                           const Eigen::Vector2d& x2);

// Fundamental matrix (x2^T F x1 = 0) of eight or more correspondences by the normalised
// eight-point algorithm (Hartley 1997: both point sets moved to their centroid and scaled to
// a mean distance of sqrt(2), the linear least-squares solution, rank 2 enforced by zeroing
// the smallest singular value). Least squares over all points given: no outlier rejection.
// Scaled to unit Frobenius norm; the zero matrix for fewer than eight points, different
// sizes, or points that leave the solution undetermined (all on a line).
Eigen::Matrix3d FundamentalFromEightPoints(std::span<const Eigen::Vector2d> points1,
                                           std::span<const Eigen::Vector2d> points2);

}  // namespace loopsfm
