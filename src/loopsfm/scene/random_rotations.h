#pragma once
// Random rotations for the tests of view-graph cleaning and rotation averaging: uniform ones,
// small noise, and outliers far from a true rotation.

#include <cmath>

#include <Eigen/Geometry>

#include "loopsfm/math/random.h"

namespace loopsfm::testing {

// Uniformly distributed over all rotations.
inline Eigen::Quaterniond RandomRotation(Random& random) {
  return Eigen::Quaterniond(random.Normal(), random.Normal(), random.Normal(), random.Normal())
      .normalized();
}

// A random rotation at least 20 degrees from `truth`: an outlier, not a lucky inlier.
inline Eigen::Quaterniond OutlierRotation(const Eigen::Quaterniond& truth, Random& random) {
  while (true) {
    const Eigen::Quaterniond rotation = RandomRotation(random);
    if (rotation.angularDistance(truth) > 20.0 * M_PI / 180.0) return rotation;
  }
}

// A random rotation whose angle is about `sigma_deg` (root mean square).
inline Eigen::Quaterniond Noise(Random& random, double sigma_deg) {
  const double axis_sigma = sigma_deg * M_PI / 180.0 / std::sqrt(3.0);
  const Eigen::Vector3d v(random.Normal(0.0, axis_sigma), random.Normal(0.0, axis_sigma),
                          random.Normal(0.0, axis_sigma));
  if (v.norm() == 0.0) return Eigen::Quaterniond::Identity();
  return Eigen::Quaterniond(Eigen::AngleAxisd(v.norm(), v.normalized()));
}

}  // namespace loopsfm::testing
