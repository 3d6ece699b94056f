#pragma once
// Minimal absolute pose: the perspective-three-point problem for a calibrated camera.
//
// Written from the formulation of Lambda Twist (Persson and Nordberg, "Lambda Twist: An
// Accurate Fast Robust Perspective Three Point (P3P) Solver", ECCV 2018): the unknown
// depths Lambda = (l1, l2, l3) of the three points satisfy
//   |l_i y_i - l_j y_j|^2 = |x_i - x_j|^2,
// three quadratic forms in Lambda. Two homogeneous combinations define a pencil of conics
// whose degenerate member (a root of a cubic) factors into two planes through the origin;
// each plane reduces the problem to a quadratic. The depths are polished by Newton's
// method and the pose follows from the two congruent triangles.
//
// This implementation evaluates every real root of the cubic and keeps the best
// conditioned line pair, and verifies every solution against the three distance
// equations, so it returns only (numerically) valid poses.

#include <array>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"

namespace loopsfm {

// Up to 4 poses cam_from_world with l_i * bearing_i = cam_from_world * point3D_i, l_i > 0.
// Bearings need not be unit length (a normalised image point (x, y, 1) works). Returns no
// solution for degenerate input: collinear world points, coincident bearings, non-finite
// values.
std::vector<Rigid3d> SolveP3P(const std::array<Eigen::Vector3d, 3>& bearings,
                              const std::array<Eigen::Vector3d, 3>& points3D_in_world);

namespace internal {
// Real roots of c3 x^3 + c2 x^2 + c1 x + c0 = 0 (lower degree when leading coefficients
// vanish), polished by Newton's method. Returns the number of roots written.
int SolveCubicReal(double c3, double c2, double c1, double c0, double roots[3]);
}  // namespace internal

}  // namespace loopsfm
