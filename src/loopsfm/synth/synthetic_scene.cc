#include "loopsfm/synth/synthetic_scene.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Pose of a camera at `center` looking at `target`, with the image's x axis horizontal.
Rigid3d LookAt(const Eigen::Vector3d& center, const Eigen::Vector3d& target) {
  const Eigen::Vector3d forward = (target - center).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d rotation;
  rotation << right, down, forward;
  return Rigid3d(Eigen::Quaterniond(rotation).normalized(), center);
}

// Fraction of the path at frame i, in [0, 1].
double PathFraction(int frame, int num_frames) {
  return num_frames > 1 ? static_cast<double>(frame) / (num_frames - 1) : 0.0;
}

Eigen::Vector3d Rgb(double r, double g, double b) { return Eigen::Vector3d(r, g, b); }

// --- cylinder -------------------------------------------------------------------------------

constexpr double kCylinderRadius = 1.0;
constexpr double kCylinderHeight = 3.0;
constexpr double kCameraCircleRadius = 4.0;
constexpr double kCameraStartHeight = 2.0;
constexpr double kCameraEndHeight = 1.5;
constexpr double kCylinderLookAtHeight = 1.2;

void BuildCylinderScene(const SynthOptions& options, SyntheticScene* scene) {
  SyntheticWorld& world = scene->world;
  Material ground;
  ground.seed = Random::SplitMix(options.seed + 1);
  ground.dark = Rgb(0.10, 0.11, 0.06);
  ground.light = Rgb(0.78, 0.74, 0.58);
  ground.noise = {1.5, 10, 0.7, 4.0, false};
  ground.contrast = 3.0;
  world.materials.push_back(ground);
  world.ground = GroundPlane{0.0, 0};

  Material skin;
  skin.seed = Random::SplitMix(options.seed + 2);
  skin.dark = Rgb(0.22, 0.07, 0.04);
  skin.light = Rgb(0.98, 0.86, 0.62);
  skin.noise = {3.0, 9, 0.7, 4.0, false};
  skin.contrast = 3.0;
  world.materials.push_back(skin);

  BumpyCylinder cylinder;
  cylinder.radius = kCylinderRadius;
  cylinder.bottom = 0.0;
  cylinder.top = kCylinderHeight;
  cylinder.bump_amplitude = 0.06;
  cylinder.bump_frequency = 1.2;
  cylinder.bump_seed = Random::SplitMix(options.seed + 3);
  cylinder.material = 1;
  world.cylinders.push_back(cylinder);

  const double arc = options.cylinder_arc_degrees * M_PI / 180.0;
  for (int i = 0; i < options.num_frames; ++i) {
    const double s = PathFraction(i, options.num_frames);
    const double angle = -0.5 * M_PI + s * arc;
    const double height = kCameraStartHeight + s * (kCameraEndHeight - kCameraStartHeight);
    const Eigen::Vector3d center(kCameraCircleRadius * std::cos(angle),
                                 kCameraCircleRadius * std::sin(angle), height);
    scene->world_from_cam.push_back(
        LookAt(center, Eigen::Vector3d(0.0, 0.0, kCylinderLookAtHeight)));
  }
}

// --- street ---------------------------------------------------------------------------------

constexpr double kBlockHalfX = 10.0;
constexpr double kBlockHalfY = 6.0;
constexpr double kStreetStandoff = 6.0;
constexpr double kStreetWidth = 16.0;
constexpr double kEyeHeight = 1.6;
constexpr double kStreetPitchDegrees = 10.0;

// A facade material with a random colour scheme and noise character.
Material RandomFacadeMaterial(Random* rng) {
  static constexpr std::array<std::array<double, 3>, 6> kPalette = {{
      {0.85, 0.78, 0.62},  // sandstone
      {0.72, 0.36, 0.26},  // brick
      {0.62, 0.66, 0.72},  // concrete blue-grey
      {0.80, 0.74, 0.45},  // ochre
      {0.55, 0.62, 0.48},  // green plaster
      {0.90, 0.88, 0.86},  // white render
  }};
  const auto& base = kPalette[rng->UniformInt(0, kPalette.size() - 1)];
  Material m;
  m.seed = rng->Engine()();
  const Eigen::Vector3d colour(base[0], base[1], base[2]);
  m.light = (colour * rng->UniformReal(0.95, 1.1)).cwiseMin(1.0);
  m.dark = colour * rng->UniformReal(0.08, 0.2);
  m.noise.frequency = rng->UniformReal(1.2, 2.5);
  m.noise.octaves = 10;
  m.noise.gain = rng->UniformReal(0.62, 0.75);
  m.noise.sharpness = rng->UniformReal(3.0, 6.0);
  m.noise.ridged = rng->UniformReal() < 0.25;
  m.contrast = rng->UniformReal(2.0, 3.5);
  return m;
}

// Splits [lo, hi] into `parts` pieces with random lengths (ratios between 0.6 and 1.4).
std::vector<double> RandomSplits(double lo, double hi, int parts, Random* rng) {
  std::vector<double> weights(parts);
  for (double& w : weights) w = rng->UniformReal(0.6, 1.4);
  double total = 0.0;
  for (double w : weights) total += w;
  std::vector<double> cuts = {lo};
  for (double w : weights) cuts.push_back(cuts.back() + (hi - lo) * w / total);
  cuts.back() = hi;
  return cuts;
}

// Position and inward (towards the block) horizontal direction at arc length s along the
// rounded rectangle kStreetStandoff outside the block, counter-clockwise, starting where the
// straight part of the south side (y < 0) begins.
void StreetPathPoint(double s, Eigen::Vector2d* position, Eigen::Vector2d* inward) {
  const double hx = kBlockHalfX, hy = kBlockHalfY, d = kStreetStandoff;
  const std::array<Eigen::Vector2d, 4> corners = {
      Eigen::Vector2d(hx, -hy), Eigen::Vector2d(hx, hy), Eigen::Vector2d(-hx, hy),
      Eigen::Vector2d(-hx, -hy)};
  const double arc = 0.5 * M_PI * d;
  const double perimeter = 4.0 * (hx + hy) + 4.0 * arc;
  s = std::fmod(s, perimeter);
  if (s < 0.0) s += perimeter;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d& a = corners[(k + 3) % 4];
    const Eigen::Vector2d& b = corners[k];
    const double side = (b - a).norm();
    const Eigen::Vector2d along = (b - a) / side;
    const Eigen::Vector2d outward(along.y(), -along.x());
    if (s <= side) {
      *position = a + s * along + d * outward;
      *inward = -outward;
      return;
    }
    s -= side;
    if (s <= arc || k == 3) {
      const double phi = std::atan2(outward.y(), outward.x()) + std::min(s, arc) / d;
      const Eigen::Vector2d radial(std::cos(phi), std::sin(phi));
      *position = b + d * radial;
      *inward = -radial;
      return;
    }
    s -= arc;
  }
}

void BuildStreetScene(const SynthOptions& options, SyntheticScene* scene) {
  SyntheticWorld& world = scene->world;
  Random rng(options.seed);
  Material asphalt;
  asphalt.seed = rng.Engine()();
  asphalt.dark = Rgb(0.06, 0.06, 0.07);
  asphalt.light = Rgb(0.62, 0.60, 0.56);
  asphalt.noise = {1.5, 10, 0.7, 4.0, false};
  asphalt.contrast = 2.5;
  world.materials.push_back(asphalt);
  world.ground = GroundPlane{0.0, 0};

  // A 3 x 2 grid of buildings filling the block, each set back a little from the street and
  // of its own height and texture, and two pillars (kiosks, columns) in front of each side.
  const std::vector<double> xs = RandomSplits(-kBlockHalfX, kBlockHalfX, 3, &rng);
  const std::vector<double> ys = RandomSplits(-kBlockHalfY, kBlockHalfY, 2, &rng);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 2; ++j) {
      TexturedBox box;
      box.min = Eigen::Vector3d(xs[i], ys[j], 0.0);
      box.max = Eigen::Vector3d(xs[i + 1], ys[j + 1], rng.UniformReal(4.5, 12.0));
      if (i == 0) box.min.x() += rng.UniformReal(0.0, 1.2);
      if (i == 2) box.max.x() -= rng.UniformReal(0.0, 1.2);
      if (j == 0) box.min.y() += rng.UniformReal(0.0, 1.2);
      if (j == 1) box.max.y() -= rng.UniformReal(0.0, 1.2);
      box.material = static_cast<int>(world.materials.size());
      world.materials.push_back(RandomFacadeMaterial(&rng));
      world.boxes.push_back(box);
    }
  }
  scene->num_block_buildings = static_cast<int>(world.boxes.size());
  for (int side = 0; side < 4; ++side) {
    for (int k = 0; k < 2; ++k) {
      const bool along_x = side % 2 == 0;
      const double half_length = along_x ? kBlockHalfX : kBlockHalfY;
      // Centre of the pillar along the side (one in each half) and out from the block.
      const double along = (k == 0 ? -1.0 : 1.0) * rng.UniformReal(0.2, 0.8) * half_length;
      const double out = (along_x ? kBlockHalfY : kBlockHalfX) + rng.UniformReal(1.5, 2.5);
      const double sign = side < 2 ? -1.0 : 1.0;
      const Eigen::Vector2d center = along_x ? Eigen::Vector2d(along, sign * out)
                                             : Eigen::Vector2d(sign * out, along);
      const double half_size = rng.UniformReal(0.3, 0.5);
      TexturedBox pillar;
      pillar.min = Eigen::Vector3d(center.x() - half_size, center.y() - half_size, 0.0);
      pillar.max = Eigen::Vector3d(center.x() + half_size, center.y() + half_size,
                                   rng.UniformReal(2.5, 4.0));
      pillar.material = static_cast<int>(world.materials.size());
      world.materials.push_back(RandomFacadeMaterial(&rng));
      world.boxes.push_back(pillar);
    }
  }

  // The eight neighbouring blocks across the streets, one building each, seen in the
  // background where the camera looks past a corner.
  for (int bx = -1; bx <= 1; ++bx) {
    for (int by = -1; by <= 1; ++by) {
      if (bx == 0 && by == 0) continue;
      const Eigen::Vector3d offset(bx * (2.0 * kBlockHalfX + kStreetWidth),
                                   by * (2.0 * kBlockHalfY + kStreetWidth), 0.0);
      TexturedBox box;
      box.min = offset + Eigen::Vector3d(-kBlockHalfX, -kBlockHalfY, 0.0);
      box.max = offset + Eigen::Vector3d(kBlockHalfX, kBlockHalfY, rng.UniformReal(8.0, 20.0));
      box.material = static_cast<int>(world.materials.size());
      world.materials.push_back(RandomFacadeMaterial(&rng));
      world.boxes.push_back(box);
    }
  }

  const double perimeter =
      4.0 * (kBlockHalfX + kBlockHalfY) + 2.0 * M_PI * kStreetStandoff;
  const double length = perimeter * (1.0 + options.street_revisit_fraction);
  const double pitch = kStreetPitchDegrees * M_PI / 180.0;
  for (int i = 0; i < options.num_frames; ++i) {
    // Start in the middle of the south side.
    const double s = kBlockHalfX + PathFraction(i, options.num_frames) * length;
    Eigen::Vector2d position, inward;
    StreetPathPoint(s, &position, &inward);
    const Eigen::Vector3d center(position.x(), position.y(), kEyeHeight);
    const Eigen::Vector3d forward(std::cos(pitch) * inward.x(), std::cos(pitch) * inward.y(),
                                  std::sin(pitch));
    scene->world_from_cam.push_back(LookAt(center, center + forward));
  }
}

}  // namespace

void SynthOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(scene == "cylinder" || scene == "street",
                         "unknown synthetic scene '{}'; use 'cylinder' or 'street'", scene);
  LOOPSFM_REQUIRE_OPTION(num_frames >= 1, "num_frames must be at least 1, got {}", num_frames);
  LOOPSFM_REQUIRE_OPTION(width >= 8 && height >= 8 && width <= 16384 && height <= 16384,
                         "image size must be between 8 and 16384 pixels per side, got {}x{}",
                         width, height);
  LOOPSFM_REQUIRE_OPTION(focal_length_factor > 0.05 && focal_length_factor < 20.0,
                         "focal_length_factor must be in (0.05, 20), got {}",
                         focal_length_factor);
  LOOPSFM_REQUIRE_OPTION(supersampling >= 1 && supersampling <= 8,
                         "supersampling must be between 1 and 8, got {}", supersampling);
  LOOPSFM_REQUIRE_OPTION(cylinder_arc_degrees > 0.0 && cylinder_arc_degrees <= 720.0,
                         "cylinder_arc_degrees must be in (0, 720], got {}",
                         cylinder_arc_degrees);
  LOOPSFM_REQUIRE_OPTION(street_revisit_fraction >= 0.0 && street_revisit_fraction <= 1.0,
                         "street_revisit_fraction must be in [0, 1], got {}",
                         street_revisit_fraction);
  LOOPSFM_REQUIRE_OPTION(fps >= 1 && fps <= 240, "fps must be between 1 and 240, got {}", fps);
  LOOPSFM_REQUIRE_OPTION(!video || (width % 2 == 0 && height % 2 == 0),
                         "video needs an even width and height (H.264 / MPEG-4 use 4:2:0 "
                         "chroma), got {}x{}",
                         width, height);
}

SyntheticScene MakeScene(const SynthOptions& options) {
  options.Check();
  SyntheticScene scene;
  scene.options = options;
  scene.camera.camera_id = 1;
  scene.camera.model_id = CameraModelId::kPinhole;
  scene.camera.width = options.width;
  scene.camera.height = options.height;
  const double focal = options.focal_length_factor * options.width;
  scene.camera.params = {focal, focal, 0.5 * options.width, 0.5 * options.height};
  scene.camera.has_prior_focal_length = true;
  if (options.scene == "cylinder") {
    BuildCylinderScene(options, &scene);
  } else {
    BuildStreetScene(options, &scene);
  }
  return scene;
}

std::string SyntheticFrameName(int frame) { return fmt::format("frame_{:06d}.png", frame); }

std::vector<TrajectoryEntry> GroundTruthTrajectory(const SyntheticScene& scene) {
  std::vector<TrajectoryEntry> entries;
  entries.reserve(scene.world_from_cam.size());
  for (int i = 0; i < scene.NumFrames(); ++i) {
    entries.push_back({SyntheticFrameName(i), scene.world_from_cam[i]});
  }
  return entries;
}

std::optional<SurfaceHit> CastPixelRay(const SyntheticScene& scene, int frame,
                                       const Eigen::Vector2d& image_point) {
  LOOPSFM_CHECK(frame >= 0 && frame < scene.NumFrames());
  const Rigid3d& world_from_cam = scene.world_from_cam[frame];
  const Eigen::Vector3d ray_in_cam = scene.camera.CamFromImg(image_point).homogeneous();
  const Eigen::Vector3d direction = (world_from_cam.rotation * ray_in_cam).normalized();
  return scene.world.CastRay(world_from_cam.translation, direction);
}

}  // namespace loopsfm
