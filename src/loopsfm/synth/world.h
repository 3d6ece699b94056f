#pragma once
// The surfaces of a synthetic scene (a ground plane, bumpy open cylinders and boxes with
// procedural textures) and the ray caster that renders them.
//
// World coordinates are metres with z up. Textures are functions of the world position of a
// surface point, so a point looks the same from every view (stable features); they are
// band-limited to the pixel footprint of each ray, so renderings do not alias.

#include <limits>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/synth/noise.h"

namespace loopsfm {

struct Material {
  // Seed of the texture noise.
  uint64_t seed = 0;
  // Albedo (linear RGB in [0, 1]) where the texture is darkest and where it is brightest.
  Eigen::Vector3d dark = Eigen::Vector3d(0.08, 0.08, 0.08);
  Eigen::Vector3d light = Eigen::Vector3d(0.92, 0.92, 0.92);
  // Octaves of the texture noise (frequency in cycles per metre).
  FractalNoiseParams noise;
  // Slope of the tanh contrast curve applied to the summed noise; larger is closer to
  // two-tone.
  double contrast = 2.0;

  // Albedo at a world point seen with the given pixel footprint (metres per pixel).
  Eigen::Vector3d Albedo(const Eigen::Vector3d& point_in_world, double footprint) const;
};

struct GroundPlane {
  // Height of the plane z = height.
  double height = 0.0;
  int material = 0;
};

// An open cylinder (no caps) around a vertical axis whose radius is displaced by smooth noise.
struct BumpyCylinder {
  // The axis passes through (x, y) = axis_xy.
  Eigen::Vector2d axis_xy = Eigen::Vector2d::Zero();
  // Radius of the undisplaced cylinder.
  double radius = 1.0;
  // Heights of the lower and upper rim.
  double bottom = 0.0;
  double top = 3.0;
  // Largest displacement of the radius (must be below radius).
  double bump_amplitude = 0.05;
  // Frequency of the displacement noise, in cycles per metre along the surface.
  double bump_frequency = 1.0;
  // Seed of the displacement noise.
  uint64_t bump_seed = 0;
  int material = 0;

  // Radius of the displaced surface in horizontal direction `dir_xy` (unit) at height z, and
  // optionally its derivatives (d radius / d angle around the axis, d radius / d z).
  double RadiusAt(const Eigen::Vector2d& dir_xy, double z,
                  Eigen::Vector2d* derivatives = nullptr) const;
  // Upper bound on the gradient norm of the implicit function (distance from the axis minus
  // RadiusAt) inside the shell radius +- bump_amplitude, used for safe ray-marching steps.
  double GradientBound() const;
};

// An axis-aligned solid box (a building).
struct TexturedBox {
  Eigen::Vector3d min = Eigen::Vector3d::Zero();
  Eigen::Vector3d max = Eigen::Vector3d::Ones();
  int material = 0;
  // The texture is the material's noise at (point - texture_origin): boxes of one material
  // with their origins at the same corner look alike (repeated facades).
  Eigen::Vector3d texture_origin = Eigen::Vector3d::Zero();
};

enum class SurfaceKind { kGround, kCylinder, kBox };

struct SurfaceHit {
  // Distance from the ray origin along the unit ray direction.
  double distance = 0.0;
  Eigen::Vector3d point_in_world = Eigen::Vector3d::Zero();
  // Unit surface normal, on the side facing the ray origin.
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  SurfaceKind kind = SurfaceKind::kGround;
  // Index of the surface among those of its kind (0 for the ground).
  int index = 0;
  int material = 0;
  // Subtracted from point_in_world where the material's texture is looked up.
  Eigen::Vector3d texture_origin = Eigen::Vector3d::Zero();
};

struct SyntheticWorld {
  std::vector<Material> materials;
  std::optional<GroundPlane> ground;
  std::vector<BumpyCylinder> cylinders;
  std::vector<TexturedBox> boxes;
  // Unit direction towards the (directional) light.
  Eigen::Vector3d light_direction = Eigen::Vector3d(0.4, 0.25, 0.88).normalized();

  // First surface hit by origin + t * direction for t in (0, max_distance]; `direction` must
  // have unit length. Cylinder hits are found by marching along the ray and refining the
  // first crossing of the displaced surface by safeguarded Newton steps to about 1e-12 m.
  std::optional<SurfaceHit> CastRay(
      const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
      double max_distance = std::numeric_limits<double>::infinity()) const;

  // Colour (linear RGB in [0, 1]) seen along a ray that hit `hit` (the sky where nullopt);
  // `pixel_angle` is the angle in radians one pixel subtends, which sets how much texture
  // detail is kept.
  Eigen::Vector3d Shade(const std::optional<SurfaceHit>& hit, const Eigen::Vector3d& direction,
                        double pixel_angle) const;
  // Shade(CastRay(origin, direction), direction, pixel_angle).
  Eigen::Vector3d Radiance(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                           double pixel_angle) const {
    return Shade(CastRay(origin, direction), direction, pixel_angle);
  }

  // Colour of the featureless sky in a direction.
  Eigen::Vector3d Sky(const Eigen::Vector3d& direction) const;
};

}  // namespace loopsfm
