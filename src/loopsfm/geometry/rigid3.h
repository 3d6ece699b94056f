#pragma once
// Rigid and similarity transforms. Names say what they map: cam_from_world maps a
// point in world coordinates to camera coordinates (COLMAP's pose convention).

#include <cstddef>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace loopsfm {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& r, const Eigen::Vector3d& t) : rotation(r), translation(t) {}

  Eigen::Matrix<double, 3, 4> ToMatrix() const {
    Eigen::Matrix<double, 3, 4> m;
    m.leftCols<3>() = rotation.toRotationMatrix();
    m.col(3) = translation;
    return m;
  }
  Rigid3d Inverse() const {
    const Eigen::Quaterniond inv = rotation.inverse();
    return Rigid3d(inv, -(inv * translation));
  }
  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const { return rotation * x + translation; }
  // Composition: (c_from_b * b_from_a) maps a to c.
  Rigid3d operator*(const Rigid3d& b_from_a) const {
    return Rigid3d((rotation * b_from_a.rotation).normalized(),
                   rotation * b_from_a.translation + translation);
  }
};

// The pose as one array of 7 doubles, the quaternion's coefficients (x, y, z, w) and then
// the translation, for an optimiser to update in place as one parameter block: the two
// members are laid out back to back (checked here).
inline double* PoseParameters(Rigid3d& pose) { return pose.rotation.coeffs().data(); }
inline const double* PoseParameters(const Rigid3d& pose) { return pose.rotation.coeffs().data(); }
static_assert(sizeof(Eigen::Quaterniond) == 4 * sizeof(double) &&
                  offsetof(Rigid3d, translation) == 4 * sizeof(double),
              "Rigid3d's translation must follow its quaternion's coefficients");

struct Sim3d {
  double scale = 1.0;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const {
    return scale * (rotation * x) + translation;
  }
  // Composition: (c_from_b * b_from_a) maps a to c.
  Sim3d operator*(const Sim3d& b_from_a) const {
    Sim3d c_from_a;
    c_from_a.scale = scale * b_from_a.scale;
    c_from_a.rotation = (rotation * b_from_a.rotation).normalized();
    c_from_a.translation = *this * b_from_a.translation;
    return c_from_a;
  }
  // A rigid transform as a similarity of scale 1, and back (the scale is dropped).
  static Sim3d FromRigid(const Rigid3d& rigid) {
    Sim3d sim;
    sim.rotation = rigid.rotation;
    sim.translation = rigid.translation;
    return sim;
  }
  Rigid3d ToRigid() const { return Rigid3d(rotation, translation); }
  // b_from_a -> a_from_b.
  Sim3d Inverse() const {
    Sim3d inverse;
    inverse.scale = 1.0 / scale;
    inverse.rotation = rotation.inverse();
    inverse.translation = -(inverse.scale * (inverse.rotation * translation));
    return inverse;
  }
};

// A camera pose after its world was moved by new_from_old: the camera frame is scaled with
// the world, so the camera sees the moved points where it saw the old ones.
inline Rigid3d TransformCamFromWorld(const Rigid3d& cam_from_old_world, const Sim3d& new_from_old) {
  // x_cam = R x_old + t and x_old = R_s^T (x_new - t_s) / s: after scaling the camera
  // frame by s, R' = R R_s^T and t' = s t - R' t_s.
  const Eigen::Quaterniond rotation =
      (cam_from_old_world.rotation * new_from_old.rotation.inverse()).normalized();
  return Rigid3d(rotation, new_from_old.scale * cam_from_old_world.translation -
                               rotation * new_from_old.translation);
}

// Angle of a rotation in degrees, in [0, 180].
// The cross-product matrix: Skew(v) * w == v.cross(w).
inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

inline double RotationAngleDegrees(const Eigen::Quaterniond& q) {
  return Eigen::AngleAxisd(q.normalized()).angle() * 180.0 / M_PI;
}

}  // namespace loopsfm
