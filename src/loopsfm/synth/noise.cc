#include "loopsfm/synth/noise.h"

#include <array>
#include <cmath>

#include <Eigen/Geometry>

#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

uint32_t HashLattice(int32_t x, int32_t y, int32_t z, uint32_t seed) {
  uint32_t h = seed ^ (static_cast<uint32_t>(x) * 0x8da6b343u) ^
               (static_cast<uint32_t>(y) * 0xd8163841u) ^ (static_cast<uint32_t>(z) * 0xcb1ab31fu);
  h ^= h >> 16;
  h *= 0x7feb352du;
  h ^= h >> 15;
  h *= 0x846ca68bu;
  h ^= h >> 16;
  return h;
}

// The 12 directions to the edge midpoints of a cube, 4 of them twice to make 16 (so that the
// low 4 bits of a hash pick one without bias worth caring about).
constexpr std::array<std::array<double, 3>, 16> kGradients = {{
    {1, 1, 0}, {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0},
    {1, 0, 1}, {-1, 0, 1}, {1, 0, -1}, {-1, 0, -1},
    {0, 1, 1}, {0, -1, 1}, {0, 1, -1}, {0, -1, -1},
    {1, 1, 0}, {0, -1, 1}, {-1, 1, 0}, {0, -1, -1},
}};

double Fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }
double FadeDerivative(double t) { return 30.0 * t * t * (t - 1.0) * (t - 1.0); }

// Rotation applied between octaves, so lattice directions of successive octaves do not line
// up (which would show as a grid on axis-aligned walls).
const Eigen::Matrix3d& OctaveRotation() {
  static const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(1.1, Eigen::Vector3d(1.0, 2.0, 3.0).normalized()).toRotationMatrix();
  return rotation;
}

// Weight of an octave with `cycles_per_pixel`: 1 up to kFullCyclesPerPixel, smoothly down to
// 0 at twice that.
double OctaveWeight(double cycles_per_pixel) {
  const double x = 2.0 - cycles_per_pixel / kFullCyclesPerPixel;
  if (x >= 1.0) return 1.0;
  if (x <= 0.0) return 0.0;
  return x * x * (3.0 - 2.0 * x);
}

}  // namespace

GradientNoise::GradientNoise(uint64_t seed)
    : seed_(static_cast<uint32_t>(Random::SplitMix(seed))) {}

double GradientNoise::operator()(const Eigen::Vector3d& p) const {
  return Evaluate<false>(p, nullptr);
}

double GradientNoise::Evaluate(const Eigen::Vector3d& p, Eigen::Vector3d* gradient) const {
  return Evaluate<true>(p, gradient);
}

template <bool kWithGradient>
double GradientNoise::Evaluate(const Eigen::Vector3d& p, Eigen::Vector3d* gradient) const {
  const double fx = std::floor(p.x()), fy = std::floor(p.y()), fz = std::floor(p.z());
  const auto ix = static_cast<int32_t>(fx), iy = static_cast<int32_t>(fy),
             iz = static_cast<int32_t>(fz);
  const double dx = p.x() - fx, dy = p.y() - fy, dz = p.z() - fz;
  // Corner gradients g[c] and their dot products k[c] with the offset from corner c, where
  // bit 0, 1, 2 of c is the x, y, z offset of the corner.
  std::array<const std::array<double, 3>*, 8> g;
  std::array<double, 8> k;
  for (int c = 0; c < 8; ++c) {
    const int cx = c & 1, cy = (c >> 1) & 1, cz = (c >> 2) & 1;
    g[c] = &kGradients[HashLattice(ix + cx, iy + cy, iz + cz, seed_) & 15u];
    k[c] = (*g[c])[0] * (dx - cx) + (*g[c])[1] * (dy - cy) + (*g[c])[2] * (dz - cz);
  }
  const double u = Fade(dx), v = Fade(dy), w = Fade(dz);
  // Trilinear blend written as a polynomial in (u, v, w).
  const double k1 = k[1] - k[0], k2 = k[2] - k[0], k3 = k[4] - k[0];
  const double k4 = k[0] - k[1] - k[2] + k[3];
  const double k5 = k[0] - k[2] - k[4] + k[6];
  const double k6 = k[0] - k[1] - k[4] + k[5];
  const double k7 = -k[0] + k[1] + k[2] - k[3] + k[4] - k[5] - k[6] + k[7];
  const double value =
      k[0] + k1 * u + k2 * v + k3 * w + k4 * u * v + k5 * v * w + k6 * w * u + k7 * u * v * w;
  if constexpr (kWithGradient) {
    // Gradient: the blended corner gradients plus the derivative of the blend weights.
    const std::array<double, 8> weights = {
        (1 - u) * (1 - v) * (1 - w), u * (1 - v) * (1 - w), (1 - u) * v * (1 - w),
        u * v * (1 - w),             (1 - u) * (1 - v) * w, u * (1 - v) * w,
        (1 - u) * v * w,             u * v * w};
    Eigen::Vector3d blended = Eigen::Vector3d::Zero();
    for (int c = 0; c < 8; ++c) {
      blended += weights[c] * Eigen::Vector3d((*g[c])[0], (*g[c])[1], (*g[c])[2]);
    }
    *gradient = blended +
                Eigen::Vector3d(FadeDerivative(dx) * (k1 + k4 * v + k6 * w + k7 * v * w),
                                FadeDerivative(dy) * (k2 + k4 * u + k5 * w + k7 * u * w),
                                FadeDerivative(dz) * (k3 + k5 * v + k6 * u + k7 * u * v));
  }
  return value;
}

double FractalNoise(const GradientNoise& noise, const Eigen::Vector3d& p,
                    const FractalNoiseParams& params, double footprint) {
  const Eigen::Matrix3d& rotation = OctaveRotation();
  Eigen::Vector3d q = p * params.frequency;
  double frequency = params.frequency;
  double amplitude = 1.0;
  double total_amplitude = 0.0;
  double sum = 0.0;
  for (int octave = 0; octave < params.octaves; ++octave) {
    const double weight = OctaveWeight(frequency * footprint);
    if (weight == 0.0) break;
    double n = noise(q);
    if (params.ridged) n = 0.17 - std::abs(n);
    if (params.sharpness > 0.0) {
      // A sigmoid like tanh, but cheaper. Octaves close to the pixel limit are sharpened less,
      // since the harmonics that sharpening adds would alias.
      const double sharpness =
          1.0 + (params.sharpness - 1.0) * OctaveWeight(1.5 * frequency * footprint);
      const double x = sharpness * n;
      n = x / std::sqrt(1.0 + x * x);
    }
    sum += weight * amplitude * n;
    total_amplitude += weight * amplitude;
    q = 2.0 * (rotation * q) + Eigen::Vector3d(17.31, -5.77, 9.13);
    frequency *= 2.0;
    amplitude *= params.gain;
  }
  return total_amplitude > 0.0 ? sum / total_amplitude : 0.0;
}

}  // namespace loopsfm
