#include "loopsfm/synth/synthetic_scene.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "loopsfm/synth/scene_building.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

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

// --- hand-held shake ------------------------------------------------------------------------

// Sinusoids summed per shake axis, with frequencies in cycles per frame (0.5 to 4 Hz at 30 fps).
constexpr int kShakeWaves = 8;
constexpr double kShakeMinFrequency = 1.0 / 60.0;
constexpr double kShakeMaxFrequency = 1.0 / 7.5;

// A smooth zero-mean random signal with unit standard deviation over time: a sum of sinusoids
// of random frequency and phase, each of amplitude sqrt(2 / kShakeWaves).
class ShakeSignal {
 public:
  explicit ShakeSignal(Random* rng) {
    for (Wave& wave : waves_) {
      wave.frequency = rng->UniformReal(kShakeMinFrequency, kShakeMaxFrequency);
      wave.phase = rng->UniformReal(0.0, 2.0 * M_PI);
    }
  }

  double operator()(int frame) const {
    double sum = 0.0;
    for (const Wave& wave : waves_) {
      sum += std::sin(2.0 * M_PI * wave.frequency * frame + wave.phase);
    }
    return std::sqrt(2.0 / kShakeWaves) * sum;
  }

 private:
  struct Wave {
    double frequency = 0.0;
    double phase = 0.0;
  };
  std::array<Wave, kShakeWaves> waves_;
};

// Turns and moves every camera by a smooth random motion in its own axes.
void AddShake(const SynthOptions& options, SyntheticScene* scene) {
  if (options.shake_degrees == 0.0 && options.shake_centimeters == 0.0) return;
  // A stream of its own, so that shaking does not change the layout drawn from options.seed.
  Random rng(Random::SplitMix(options.seed ^ 0x7368616b65ull));
  std::vector<ShakeSignal> signals;
  for (int axis = 0; axis < 6; ++axis) signals.emplace_back(&rng);
  const double radians = options.shake_degrees * M_PI / 180.0;
  const double metres = 0.01 * options.shake_centimeters;
  for (int i = 0; i < scene->NumFrames(); ++i) {
    const Eigen::Vector3d rotation_vector =
        radians * Eigen::Vector3d(signals[0](i), signals[1](i), signals[2](i));
    const double angle = rotation_vector.norm();
    Rigid3d cam_from_shaken;
    if (angle > 0.0) {
      cam_from_shaken.rotation = Eigen::AngleAxisd(angle, rotation_vector / angle);
    }
    cam_from_shaken.translation =
        metres * Eigen::Vector3d(signals[3](i), signals[4](i), signals[5](i));
    scene->world_from_cam[i] = scene->world_from_cam[i] * cam_from_shaken;
  }
}

}  // namespace

Rigid3d LookAt(const Eigen::Vector3d& center, const Eigen::Vector3d& target) {
  const Eigen::Vector3d forward = (target - center).normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d rotation;
  rotation << right, down, forward;
  return Rigid3d(Eigen::Quaterniond(rotation).normalized(), center);
}

double PathFraction(int frame, int num_frames) {
  return num_frames > 1 ? static_cast<double>(frame) / (num_frames - 1) : 0.0;
}

void SynthOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(scene == "cylinder" || scene == "street",
                         "unknown synthetic scene '{}'; use 'cylinder' or 'street'", scene);
  LOOPSFM_REQUIRE_OPTION(num_frames >= 1, "num_frames must be at least 1, got {}", num_frames);
  LOOPSFM_REQUIRE_OPTION(width >= 8 && height >= 8 && width <= 16384 && height <= 16384,
                         "image size must be between 8 and 16384 pixels per side, got {}x{}",
                         width, height);
  LOOPSFM_REQUIRE_OPTION(focal_length_factor > 0.05 && focal_length_factor < 20.0,
                         "the focal length factor (--focal-factor, focal length / image width) must "
                         "be in (0.05, 20), got {}",
                         focal_length_factor);
  MakeSynthCamera(lens, width, height, focal_length_factor);  // throws for a bad lens
  LOOPSFM_REQUIRE_OPTION(supersampling >= 1 && supersampling <= 8,
                         "supersampling must be between 1 and 8, got {}", supersampling);
  LOOPSFM_REQUIRE_OPTION(cylinder_arc_degrees > 0.0 && cylinder_arc_degrees <= 720.0,
                         "cylinder_arc_degrees must be in (0, 720], got {}",
                         cylinder_arc_degrees);
  LOOPSFM_REQUIRE_OPTION(street_revisit_fraction >= 0.0 && street_revisit_fraction <= 1.0,
                         "street_revisit_fraction must be in [0, 1], got {}",
                         street_revisit_fraction);
  LOOPSFM_REQUIRE_OPTION(street_laps >= 0 && street_laps <= 100,
                         "street_laps must be between 0 and 100, got {}", street_laps);
  LOOPSFM_REQUIRE_OPTION(street_laps + street_revisit_fraction > 0.0,
                         "a street walk needs --laps 1 or more or a --revisit fraction above 0");
  LOOPSFM_REQUIRE_OPTION(
      street_route == "block" || street_route == "figure8" || street_route == "avenue" ||
          street_route == "pan",
      "unknown street route '{}'; use 'block', 'figure8', 'avenue' or 'pan'", street_route);
  LOOPSFM_REQUIRE_OPTION(street_route != "pan" || (street_look_ahead_degrees == 0.0 &&
                                                   !street_abrupt_turns),
                         "the pan route turns on the spot: street_look_ahead_degrees and "
                         "street_abrupt_turns do not apply to it");
  LOOPSFM_REQUIRE_OPTION(street_route != "avenue" || !street_abrupt_turns,
                         "the avenue route is straight: street_abrupt_turns does not apply to it");
  LOOPSFM_REQUIRE_OPTION(street_look_ahead_degrees >= 0.0 && street_look_ahead_degrees <= 60.0,
                         "street_look_ahead_degrees must be in [0, 60], got {}",
                         street_look_ahead_degrees);
  // Measured on the figure-eight at 0.3 m a frame: with 30 degrees, 14 to 47 of 100 pairs of
  // frames across each 90-degree turn have 30 or more SIFT matches consistent with an epipolar
  // geometry; with 20, 7 to 34; with 0, none.
  LOOPSFM_REQUIRE_OPTION(!street_abrupt_turns || street_look_ahead_degrees >= 20.0,
                         "street_abrupt_turns needs street_look_ahead_degrees of at least 20 "
                         "(30 is a good choice), got {}: frames before and after a 90-degree "
                         "turn that look straight at the facades share too little to match",
                         street_look_ahead_degrees);
  LOOPSFM_REQUIRE_OPTION(scene == "street" || (street_laps == 1 && street_route == "block" &&
                                               street_look_ahead_degrees == 0.0 &&
                                               !street_abrupt_turns && !street_repeated_facades),
                         "street_laps, street_route, street_look_ahead_degrees and "
                         "street_abrupt_turns apply to the street scene only, not to '{}'",
                         scene);
  LOOPSFM_REQUIRE_OPTION(shake_degrees >= 0.0 && shake_degrees <= 10.0,
                         "shake_degrees must be in [0, 10], got {}", shake_degrees);
  LOOPSFM_REQUIRE_OPTION(shake_centimeters >= 0.0 && shake_centimeters <= 100.0,
                         "shake_centimeters must be in [0, 100], got {}", shake_centimeters);
  degradation.Check();
  LOOPSFM_REQUIRE_OPTION(degradation.LastFrameNamed() < num_frames,
                         "a degradation range names frame {}, but the frames are 0 to {}",
                         degradation.LastFrameNamed(), num_frames - 1);
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
  scene.camera =
      MakeSynthCamera(options.lens, options.width, options.height, options.focal_length_factor);
  if (options.scene == "cylinder") {
    BuildCylinderScene(options, &scene);
  } else {
    BuildStreetScene(options, &scene);
  }
  AddShake(options, &scene);
  return scene;
}

std::string SyntheticFrameName(int frame) { return fmt::format("frame_{:06d}.png", frame); }

std::string SyntheticFrameName(const SynthOptions& options, int frame) {
  const bool jpeg = options.degradation.jpeg_quality > 0 && !options.video;
  return fmt::format("frame_{:06d}.{}", frame, jpeg ? "jpg" : "png");
}

std::vector<TrajectoryEntry> GroundTruthTrajectory(const SyntheticScene& scene) {
  std::vector<TrajectoryEntry> entries;
  entries.reserve(scene.world_from_cam.size());
  for (int i = 0; i < scene.NumFrames(); ++i) {
    entries.push_back({SyntheticFrameName(scene.options, i), scene.world_from_cam[i]});
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

Eigen::Vector2d ImageMotion(const SyntheticScene& scene, int frame) {
  LOOPSFM_CHECK(frame >= 0 && frame < scene.NumFrames());
  const int n = scene.NumFrames();
  if (n < 2) return Eigen::Vector2d::Zero();
  auto turn_to = [&](int other) {
    return RotationAngleDegrees(scene.world_from_cam[frame].rotation.inverse() *
                                scene.world_from_cam[other].rotation);
  };
  // The next frame, unless the view turns clearly less towards the previous one.
  int other = frame + 1;
  if (other == n || (frame > 0 && turn_to(frame - 1) + 1.0 < turn_to(frame + 1))) {
    other = frame - 1;
  }
  const Rigid3d other_from_world = scene.world_from_cam[other].Inverse();
  constexpr int kGrid = 8;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  int count = 0;
  for (int gy = 0; gy < kGrid; ++gy) {
    for (int gx = 0; gx < kGrid; ++gx) {
      const Eigen::Vector2d pixel((gx + 0.5) * scene.camera.width / kGrid,
                                  (gy + 0.5) * scene.camera.height / kGrid);
      const std::optional<SurfaceHit> hit = CastPixelRay(scene, frame, pixel);
      if (!hit) continue;
      const Eigen::Vector3d in_other = other_from_world * hit->point_in_world;
      if (in_other.z() <= 1e-6) continue;
      sum += scene.camera.ImgFromCam(in_other) - pixel;
      ++count;
    }
  }
  if (count == 0) return Eigen::Vector2d::Zero();
  return (other > frame ? 1.0 : -1.0) * sum / count;
}

}  // namespace loopsfm
