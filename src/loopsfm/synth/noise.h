#pragma once
// Seeded procedural noise for synthetic textures and surface displacement.
//
// GradientNoise is lattice gradient noise in 3D: a pseudo-random gradient at every integer
// lattice point (one of the 12 cube-edge directions, chosen by hashing the lattice point with
// the seed, so no table is stored), blended with a quintic fade. FractalNoise sums octaves of
// it and drops the octaves finer than a pixel can show, so textures stay band-limited (free of
// aliasing) at any viewing distance.

#include <cstdint>

#include <Eigen/Core>

namespace loopsfm {

class GradientNoise {
 public:
  explicit GradientNoise(uint64_t seed);

  // Smooth noise in about [-1, 1] (typically within +-0.5) with features about one unit
  // across; zero at lattice points.
  double operator()(const Eigen::Vector3d& p) const;
  // The noise and its exact gradient at p.
  double Evaluate(const Eigen::Vector3d& p, Eigen::Vector3d* gradient) const;

 private:
  template <bool kWithGradient>
  double Evaluate(const Eigen::Vector3d& p, Eigen::Vector3d* gradient) const;

  uint32_t seed_;
};

struct FractalNoiseParams {
  // Frequency of the coarsest octave, in cycles per unit of the input.
  double frequency = 1.0;
  // Most octaves summed; each doubles the frequency of the previous one.
  int octaves = 6;
  // Amplitude ratio of successive octaves.
  double gain = 0.5;
  // When positive, each octave n is shaped by a sigmoid, x / sqrt(1 + x^2) with
  // x = sharpness * n, before summing, which turns soft noise into crisp blobs at every scale
  // (good for blob detectors such as SIFT). Octaves near the pixel limit are sharpened less.
  double sharpness = 0.0;
  // Each octave n is folded to 0.17 - |n| (vein-like ridges, about half the area dark) before
  // shaping.
  bool ridged = false;
};

// Weighted sum of shaped octaves of `noise` at p, divided by the sum of the weights (so the
// result lies in about [-1, 1] and keeps its contrast at any distance). `footprint` is the
// size of one pixel at p in input units: octaves with more than kFullCyclesPerPixel cycles per
// pixel fade out, and those with more than twice that are skipped. Pass footprint = 0 for the
// full sum.
double FractalNoise(const GradientNoise& noise, const Eigen::Vector3d& p,
                    const FractalNoiseParams& params, double footprint = 0.0);

// Finest detail kept at full strength, in cycles per pixel (well below the Nyquist limit of
// 0.5, since shaped octaves carry harmonics above their base frequency).
inline constexpr double kFullCyclesPerPixel = 0.15;

}  // namespace loopsfm
