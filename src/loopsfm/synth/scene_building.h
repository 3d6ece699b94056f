#pragma once
// Internal to synth/: what the scene builders of synthetic_scene.cc and street_scene.cc share.

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/synth/synthetic_scene.h"

namespace loopsfm {

// Pose of a camera at `center` looking at `target`, with the image's x axis horizontal.
Rigid3d LookAt(const Eigen::Vector3d& center, const Eigen::Vector3d& target);

inline Eigen::Vector3d Rgb(double r, double g, double b) { return Eigen::Vector3d(r, g, b); }

// Fraction of the path at frame i, in [0, 1].
double PathFraction(int frame, int num_frames);

// The street scene's world and camera path (street_scene.cc).
void BuildStreetScene(const SynthOptions& options, SyntheticScene* scene);

}  // namespace loopsfm
