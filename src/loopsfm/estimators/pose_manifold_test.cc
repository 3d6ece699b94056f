#include "loopsfm/estimators/pose_manifold.h"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace loopsfm {
namespace {

using Vector7d = Eigen::Matrix<double, 7, 1>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

// A pose 40 units from the world's origin, where the tangent's choice matters.
Vector7d FarPose() {
  const Eigen::Quaterniond q =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, -1.0, 0.4).normalized()));
  const Eigen::Vector3d centre(25.0, -12.0, 30.0);
  Vector7d x;
  x.head<4>() = q.coeffs();
  x.tail<3>() = -(q * centre);
  return x;
}

Eigen::Vector3d Centre(const Vector7d& x) {
  const Eigen::Map<const Eigen::Quaterniond> q(x.data());
  return -(q.conjugate() * x.tail<3>());
}

TEST(PoseCentreManifold, TurnKeepsTheCentreAndMoveShiftsIt) {
  const PoseCentreManifold manifold;
  const Vector7d x = FarPose();
  Vector6d delta;
  delta << 0.2, -0.1, 0.3, 0.0, 0.0, 0.0;
  Vector7d turned;
  ASSERT_TRUE(manifold.Plus(x.data(), delta.data(), turned.data()));
  EXPECT_LT((Centre(turned) - Centre(x)).norm(), 1e-12);
  const Eigen::Quaterniond expected =
      Eigen::Quaterniond(Eigen::AngleAxisd(delta.head<3>().norm(), delta.head<3>().normalized())) *
      Eigen::Map<const Eigen::Quaterniond>(x.data());
  EXPECT_LT(Eigen::Map<const Eigen::Quaterniond>(turned.data()).angularDistance(expected), 1e-12);

  delta << 0.0, 0.0, 0.0, 1.5, -2.0, 0.25;
  Vector7d moved;
  ASSERT_TRUE(manifold.Plus(x.data(), delta.data(), moved.data()));
  EXPECT_LT((Centre(moved) - Centre(x) - delta.tail<3>()).norm(), 1e-12);
  EXPECT_LT((moved.head<4>() - x.head<4>()).norm(), 1e-14);
}

TEST(PoseCentreManifold, MinusUndoesPlus) {
  const PoseCentreManifold manifold;
  const Vector7d x = FarPose();
  Vector6d delta;
  delta << -0.4, 0.25, 0.1, 3.0, 0.5, -1.0;
  Vector7d y;
  ASSERT_TRUE(manifold.Plus(x.data(), delta.data(), y.data()));
  Vector6d back;
  ASSERT_TRUE(manifold.Minus(y.data(), x.data(), back.data()));
  EXPECT_LT((back - delta).norm(), 1e-12);
}

TEST(PoseCentreManifold, JacobiansMatchFiniteDifferences) {
  const PoseCentreManifold manifold;
  const Vector7d x = FarPose();
  Eigen::Matrix<double, 7, 6, Eigen::RowMajor> plus;
  ASSERT_TRUE(manifold.PlusJacobian(x.data(), plus.data()));
  const double h = 1e-6;
  for (int k = 0; k < 6; ++k) {
    Vector6d step = Vector6d::Zero();
    step[k] = h;
    Vector7d forward, backward;
    manifold.Plus(x.data(), step.data(), forward.data());
    step[k] = -h;
    manifold.Plus(x.data(), step.data(), backward.data());
    const Vector7d numeric = (forward - backward) / (2 * h);
    EXPECT_LT((plus.col(k) - numeric).norm(), 1e-6 * (1.0 + numeric.norm())) << "column " << k;
  }
  Eigen::Matrix<double, 6, 7, Eigen::RowMajor> minus;
  ASSERT_TRUE(manifold.MinusJacobian(x.data(), minus.data()));
  EXPECT_LT((minus * plus - Eigen::Matrix<double, 6, 6>::Identity()).norm(), 1e-9);
}

}  // namespace
}  // namespace loopsfm
