// The street scene: blocks of textured box buildings and a walk around them.
//
// Block A spans [-kBlockHalfX, kBlockHalfX] x [-kBlockHalfY, kBlockHalfY]. The walk runs on a
// rounded rectangle kStreetStandoff outside a block: straight along each side, then a quarter
// circle around the block's corner. The "figure8" route walks around A counter-clockwise, then
// around block B, A's mirror image across the street east of A, clockwise: that street is
// 2 * kStreetStandoff wide, so the loops around A and B share its centre line, walked north
// in both. The camera films the block it walks around, so at the two corners where the route
// passes from one loop to the other the view swings the other way to the path. The "avenue"
// route never comes back: it walks straight east along the south side of a row of blocks
// shaped like A, one every 2 * kBlockHalfX + kStreetWidth with cross streets between them,
// kStreetStandoff from their south faces, filming them; as many blocks as the walk needs and
// one more ahead. The "pan" route does not walk: the camera stands where the walk would start
// and turns on the spot.

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "loopsfm/math/random.h"
#include "loopsfm/synth/scene_building.h"

namespace loopsfm {
namespace {

constexpr double kBlockHalfX = 10.0;
constexpr double kBlockHalfY = 6.0;
constexpr double kStreetStandoff = 6.0;
constexpr double kStreetWidth = 16.0;
constexpr double kEyeHeight = 1.6;
constexpr double kStreetPitchDegrees = 10.0;
// The "pan" route turns the view on the spot by this much (no baseline at all).
constexpr double kPanDegrees = 120.0;
// The loop around block B is the mirror image of the loop around A across x = kMirrorX, the
// centre line of the street between them.
constexpr double kMirrorX = kBlockHalfX + kStreetStandoff;

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

void AddBox(const Eigen::Vector3d& min, const Eigen::Vector3d& max, Random* rng,
            SyntheticWorld* world) {
  TexturedBox box;
  box.min = min;
  box.max = max;
  box.material = static_cast<int>(world->materials.size());
  world->materials.push_back(RandomFacadeMaterial(rng));
  world->boxes.push_back(box);
}

// A 3 x 2 grid of identical buildings: one size, one material, the texture anchored at
// each building's corner.
void AddRepeatedBlockBuildings(const Eigen::Vector2d& center, Random* rng, SyntheticWorld* world) {
  const int material = static_cast<int>(world->materials.size());
  world->materials.push_back(RandomFacadeMaterial(rng));
  const double width = 2.0 * kBlockHalfX / 3.0, depth = kBlockHalfY;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 2; ++j) {
      TexturedBox box;
      box.min = Eigen::Vector3d(center.x() - kBlockHalfX + i * width + 0.3,
                                center.y() - kBlockHalfY + j * depth + 0.3, 0.0);
      box.max = box.min + Eigen::Vector3d(width - 0.6, depth - 0.6, 9.0);
      box.material = material;
      box.texture_origin = box.min;
      world->boxes.push_back(box);
    }
  }
}

// A 3 x 2 grid of buildings filling the block centred at `center`, each set back a little
// from the street and of its own height and texture.
void AddBlockBuildings(const Eigen::Vector2d& center, Random* rng, SyntheticWorld* world) {
  const std::vector<double> xs =
      RandomSplits(center.x() - kBlockHalfX, center.x() + kBlockHalfX, 3, rng);
  const std::vector<double> ys =
      RandomSplits(center.y() - kBlockHalfY, center.y() + kBlockHalfY, 2, rng);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 2; ++j) {
      Eigen::Vector3d min(xs[i], ys[j], 0.0);
      Eigen::Vector3d max(xs[i + 1], ys[j + 1], rng->UniformReal(4.5, 12.0));
      if (i == 0) min.x() += rng->UniformReal(0.0, 1.2);
      if (i == 2) max.x() -= rng->UniformReal(0.0, 1.2);
      if (j == 0) min.y() += rng->UniformReal(0.0, 1.2);
      if (j == 1) max.y() -= rng->UniformReal(0.0, 1.2);
      AddBox(min, max, rng, world);
    }
  }
}

// Two pillars (kiosks, columns) in front of each side of the block centred at `center`.
void AddPillars(const Eigen::Vector2d& center, Random* rng, SyntheticWorld* world) {
  for (int side = 0; side < 4; ++side) {
    for (int k = 0; k < 2; ++k) {
      const bool along_x = side % 2 == 0;
      const double half_length = along_x ? kBlockHalfX : kBlockHalfY;
      // Centre of the pillar along the side (one in each half) and out from the block.
      const double along = (k == 0 ? -1.0 : 1.0) * rng->UniformReal(0.2, 0.8) * half_length;
      const double out = (along_x ? kBlockHalfY : kBlockHalfX) + rng->UniformReal(1.5, 2.5);
      const double sign = side < 2 ? -1.0 : 1.0;
      const Eigen::Vector2d xy = center + (along_x ? Eigen::Vector2d(along, sign * out)
                                                   : Eigen::Vector2d(sign * out, along));
      const double half_size = rng->UniformReal(0.3, 0.5);
      AddBox(Eigen::Vector3d(xy.x() - half_size, xy.y() - half_size, 0.0),
             Eigen::Vector3d(xy.x() + half_size, xy.y() + half_size, rng->UniformReal(2.5, 4.0)),
             rng, world);
    }
  }
}

// One building filling the block centred at `center` (a block across a street).
void AddNeighbour(const Eigen::Vector2d& center, Random* rng, SyntheticWorld* world) {
  const Eigen::Vector3d offset(center.x(), center.y(), 0.0);
  AddBox(offset + Eigen::Vector3d(-kBlockHalfX, -kBlockHalfY, 0.0),
         offset + Eigen::Vector3d(kBlockHalfX, kBlockHalfY, rng->UniformReal(8.0, 20.0)), rng,
         world);
}

// Where the walk is on the loop around block A (counter-clockwise, arc length s from where
// the straight part of the south side begins).
struct LoopPoint {
  Eigen::Vector2d position;
  // Horizontal unit direction towards the block: the side's normal, or towards the corner.
  Eigen::Vector2d inward;
  // The side (0 south, 1 east, 2 north, 3 west) or the arc after it, around its end corner.
  int segment = 0;
  bool on_arc = false;
};

std::array<Eigen::Vector2d, 4> BlockCorners() {
  const double hx = kBlockHalfX, hy = kBlockHalfY;
  return {Eigen::Vector2d(hx, -hy), Eigen::Vector2d(hx, hy), Eigen::Vector2d(-hx, hy),
          Eigen::Vector2d(-hx, -hy)};
}

// Unit normal of side k of block A pointing into the block.
Eigen::Vector2d SideInward(int k) {
  const std::array<Eigen::Vector2d, 4> corners = BlockCorners();
  const Eigen::Vector2d along = (corners[k % 4] - corners[(k + 3) % 4]).normalized();
  return Eigen::Vector2d(-along.y(), along.x());
}

double LoopLength() {
  return 4.0 * (kBlockHalfX + kBlockHalfY) + 4.0 * (0.5 * M_PI * kStreetStandoff);
}

LoopPoint StreetLoopPoint(double s) {
  const double d = kStreetStandoff;
  const std::array<Eigen::Vector2d, 4> corners = BlockCorners();
  const double arc = 0.5 * M_PI * d;
  const double perimeter = LoopLength();
  s = std::fmod(s, perimeter);
  if (s < 0.0) s += perimeter;
  LoopPoint point;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d& a = corners[(k + 3) % 4];
    const Eigen::Vector2d& b = corners[k];
    const double side = (b - a).norm();
    const Eigen::Vector2d along = (b - a) / side;
    const Eigen::Vector2d outward(along.y(), -along.x());
    point.segment = k;
    if (s <= side) {
      point.position = a + s * along + d * outward;
      point.inward = -outward;
      return point;
    }
    s -= side;
    if (s <= arc || k == 3) {
      const double phi = std::atan2(outward.y(), outward.x()) + std::min(s, arc) / d;
      const Eigen::Vector2d radial(std::cos(phi), std::sin(phi));
      point.position = b + d * radial;
      point.inward = -radial;
      point.on_arc = true;
      return point;
    }
    s -= arc;
  }
  return point;  // not reached: the loop above returns on the last arc
}

Eigen::Vector2d Rotate(const Eigen::Vector2d& v, double radians) {
  if (radians == 0.0) return v;
  const double c = std::cos(radians), s = std::sin(radians);
  return Eigen::Vector2d(c * v.x() - s * v.y(), s * v.x() + c * v.y());
}

Eigen::Vector2d Mirror(const Eigen::Vector2d& direction) {
  return Eigen::Vector2d(-direction.x(), direction.y());
}

// Horizontal viewing direction at `point` of the loop around A. `look_ahead` (radians) turns
// the view from the block towards the walking direction. On the arc after the south side,
// `junction` says the route goes on around block B, whose view (mirrored) comes next.
Eigen::Vector2d ViewDirection(const LoopPoint& point, double look_ahead, bool abrupt,
                              bool junction) {
  if (!point.on_arc) return Rotate(point.inward, -look_ahead);
  if (!abrupt && !junction) return Rotate(point.inward, -look_ahead);
  const Eigen::Vector2d from = Rotate(SideInward(point.segment), -look_ahead);
  Eigen::Vector2d to = Rotate(SideInward(point.segment + 1), -look_ahead);
  if (junction) to = Mirror(to);
  if (abrupt) return to;
  // Smooth junction: the view turns from `from` to `to` (by the smaller angle) at a constant
  // rate along the arc, as the path turns: the fraction of the arc walked is the angle the
  // inward direction has turned.
  const Eigen::Vector2d start = SideInward(point.segment);
  const double walked =
      std::abs(std::atan2(start.x() * point.inward.y() - start.y() * point.inward.x(),
                          start.dot(point.inward))) / (0.5 * M_PI);
  const double turn = std::atan2(from.x() * to.y() - from.y() * to.x(), from.dot(to));
  return Rotate(from, walked * turn);
}

// Position and horizontal viewing direction at arc length u along the route; for "pan", at
// the fraction u of the sweep.
void StreetRoutePoint(const SynthOptions& options, double u, Eigen::Vector2d* position,
                      Eigen::Vector2d* view) {
  const double look_ahead = options.street_look_ahead_degrees * M_PI / 180.0;
  const bool abrupt = options.street_abrupt_turns;
  if (options.street_route == "pan") {
    // Where the walk would start, facing the block; the view turns from left to right.
    const LoopPoint start = StreetLoopPoint(kBlockHalfX);
    *position = start.position;
    *view = Rotate(start.inward, (0.5 - u) * kPanDegrees * M_PI / 180.0);
    return;
  }
  if (options.street_route == "avenue") {
    // Along the south side of the row of blocks, where the loop around A walks its south side.
    *position = Eigen::Vector2d(u - kBlockHalfX, -kBlockHalfY - kStreetStandoff);
    *view = Rotate(Eigen::Vector2d::UnitY(), -look_ahead);
    return;
  }
  if (options.street_route == "block") {
    const LoopPoint point = StreetLoopPoint(u);
    *position = point.position;
    *view = ViewDirection(point, look_ahead, abrupt, false);
    return;
  }
  // Figure-eight: A's loop from the foot of the street between A and B (where the arc after
  // A's south side ends; u = middle_street_start - loop there), then B's loop from the same
  // place (u = middle_street_start), so u in A's loop is its arc length as for "block".
  const double loop = LoopLength();
  const double middle_street_start = 2.0 * kBlockHalfX + 0.5 * M_PI * kStreetStandoff;
  double w = std::fmod(u - middle_street_start + loop, 2.0 * loop);
  if (w < 0.0) w += 2.0 * loop;
  const bool around_b = w >= loop;
  const LoopPoint point = StreetLoopPoint(middle_street_start + (around_b ? w - loop : w));
  const bool junction = point.on_arc && point.segment == 0;
  *position = point.position;
  *view = ViewDirection(point, look_ahead, abrupt, junction);
  if (around_b) {
    position->x() = 2.0 * kMirrorX - position->x();
    *view = Mirror(*view);
  }
}

}  // namespace

void BuildStreetScene(const SynthOptions& options, SyntheticScene* scene) {
  SyntheticWorld& world = scene->world;
  const bool figure8 = options.street_route == "figure8";
  const bool avenue = options.street_route == "avenue";
  Random rng(options.seed);
  Material asphalt;
  asphalt.seed = rng.Engine()();
  asphalt.dark = Rgb(0.06, 0.06, 0.07);
  asphalt.light = Rgb(0.62, 0.60, 0.56);
  asphalt.noise = {1.5, 10, 0.7, 4.0, false};
  asphalt.contrast = 2.5;
  world.materials.push_back(asphalt);
  world.ground = GroundPlane{0.0, 0};

  const double pitch_x = 2.0 * kBlockHalfX + kStreetWidth;
  const double pitch_y = 2.0 * kBlockHalfY + kStreetWidth;
  const double perimeter =
      4.0 * (kBlockHalfX + kBlockHalfY) + 2.0 * M_PI * kStreetStandoff;
  const double route = figure8 ? 2.0 * perimeter : perimeter;
  const double length = route * (options.street_laps + options.street_revisit_fraction);

  // The blocks walked around (or along): buildings first, then pillars in front of them.
  std::vector<Eigen::Vector2d> blocks = {Eigen::Vector2d::Zero()};
  if (figure8) blocks.emplace_back(2.0 * kMirrorX, 0.0);
  if (avenue) {
    // Every block whose south face the walk passes (from the middle of the first, `length`
    // metres east), and one more ahead.
    const int count = static_cast<int>(std::ceil((length + kBlockHalfX) / pitch_x)) + 1;
    for (int k = 1; k < count; ++k) blocks.emplace_back(k * pitch_x, 0.0);
  }
  const auto add_buildings =
      options.street_repeated_facades ? AddRepeatedBlockBuildings : AddBlockBuildings;
  for (const Eigen::Vector2d& block : blocks) add_buildings(block, &rng, &world);
  scene->num_block_buildings = static_cast<int>(world.boxes.size());
  for (const Eigen::Vector2d& block : blocks) AddPillars(block, &rng, &world);

  if (avenue) {
    // The neighbouring blocks, one building each: a row north of the avenue's blocks, seen
    // through the cross streets, and a row across the avenue, both a block longer at each end.
    const int count = static_cast<int>(blocks.size());
    for (int bx = -1; bx <= count; ++bx) {
      for (const double y : {-pitch_y, pitch_y}) {
        AddNeighbour(Eigen::Vector2d(bx * pitch_x, y), &rng, &world);
      }
    }
  } else {
    // The neighbouring blocks across the streets, one building each, seen in the background
    // where the camera looks past a corner: a ring of blocks around A (or around A and B).
    for (int bx = -1; bx <= (figure8 ? 2 : 1); ++bx) {
      for (int by = -1; by <= 1; ++by) {
        if ((bx == 0 || (figure8 && bx == 1)) && by == 0) continue;
        // Columns 0 and 1 are A's and B's; column 2 lies one street east of B.
        double x = bx * pitch_x;
        if (figure8 && bx >= 1) x = blocks[1].x() + (bx - 1) * pitch_x;
        AddNeighbour(Eigen::Vector2d(x, by * pitch_y), &rng, &world);
      }
    }
  }

  const double pitch = kStreetPitchDegrees * M_PI / 180.0;
  for (int i = 0; i < options.num_frames; ++i) {
    // Start in the middle of the south side of block A.
    const double u = options.street_route == "pan"
                         ? PathFraction(i, options.num_frames)
                         : kBlockHalfX + PathFraction(i, options.num_frames) * length;
    Eigen::Vector2d position, view;
    StreetRoutePoint(options, u, &position, &view);
    const Eigen::Vector3d center(position.x(), position.y(), kEyeHeight);
    const Eigen::Vector3d forward(std::cos(pitch) * view.x(), std::cos(pitch) * view.y(),
                                  std::sin(pitch));
    scene->world_from_cam.push_back(LookAt(center, center + forward));
  }
}

}  // namespace loopsfm
