#pragma once
// The tangent space bundle adjustment moves a camera pose in: a pose is stored as
// cam_from_world, 7 numbers (quaternion coefficients x, y, z, w, then the translation t,
// PoseParameters in geometry/rigid3.h), and a step is a rotation vector (applied in the
// camera's frame) and a move of the camera's centre c = -R^T t, both 3-vectors.
//
// Why the centre: with steps in t (ceres::EuclideanManifold), turning a camera about its own
// centre takes a step in t as long as the turn times the distance to the world's origin,
// linear only to first order; far from the origin every rotation step then misplaces the
// camera by half the squared angle times that distance, and Levenberg-Marquardt's model of
// the cost is off where the map is weak (block.mp4 after a loop closing, 50 units from the
// origin: a bundle took 100 iterations with gain ratios of 0.3-0.7). In the centre's
// tangent a turn leaves the centre in place exactly, and a prior on a centre coordinate (the
// scale gauge) is linear in the step.
#include <ceres/manifold.h>

namespace loopsfm {

class PoseCentreManifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 7; }
  int TangentSize() const override { return 6; }
  // x_plus_delta: rotation Exp(delta[0..2]) * R, centre c + delta[3..5].
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  // 7 x 6, row-major, at delta = 0.
  bool PlusJacobian(const double* x, double* jacobian) const override;
  // The step from x to y: the rotation vector of R_y * R_x^T and c_y - c_x.
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  // 6 x 7, row-major: the left pseudo-inverse of PlusJacobian (exact along the manifold).
  bool MinusJacobian(const double* x, double* jacobian) const override;
};

}  // namespace loopsfm
