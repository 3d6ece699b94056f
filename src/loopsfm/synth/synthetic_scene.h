#pragma once
// Synthetic scenes with exact ground truth: the camera, the pose of every frame and the
// surfaces, so that tests and benchmarks can check poses and 3D points against the truth.
//
//   cylinder  an open cylinder with a bumpy, noise-textured surface standing on a textured
//             ground plane; the camera circles it a little more than once (380 degrees by
//             default), looking at it and sinking slowly, so the last frames see what the
//             first frames saw from a bit lower (a loop).
//   street    a block of box buildings with noise-textured facades (a different texture per
//             building), pillars in front of it and blocks across the streets; the camera
//             walks around the block 6 m from it, looking sideways at the facades, and at the
//             end walks the first 10% of the loop again. Options make the walk harder: more
//             laps, a figure-eight around two blocks, a view turned ahead, headings that jump
//             by 90 degrees at the corners, hand-held shake (see SynthOptions); or the
//             camera walks straight along a row of blocks and never comes back (an avenue).
//
// Frame degradations (noise, motion blur, haze, dark frames, JPEG) are applied to the
// rendered frames (frame_degradation.h); the poses are not affected by them. The lens may
// distort (lens.h): every pixel's ray is unprojected through the camera model.
//
// World coordinates are metres with z up. Poses use OpenCV camera axes (x right, y down,
// z forward); image coordinates follow COLMAP (the centre of the top-left pixel is (0.5, 0.5)).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/math/random.h"
#include "loopsfm/scene/camera.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/synth/frame_degradation.h"
#include "loopsfm/synth/lens.h"
#include "loopsfm/synth/world.h"

namespace loopsfm {

struct SynthOptions {
  // Which scene to build: "cylinder" or "street".
  std::string scene = "cylinder";
  // Number of frames along the camera path.
  int num_frames = 150;
  // Image size in pixels.
  int width = 640;
  int height = 480;
  // Focal length in pixels as a multiple of the image width (0.9 gives a 58 degree field).
  double focal_length_factor = 0.9;
  // Lens: camera model and distortion coefficients (see lens.h); the default PINHOLE renders
  // without distortion. Each pixel's ray goes through the model, so the frames are distorted.
  LensOptions lens;
  // Rays per pixel along each axis for pixels on an edge (2 means 2x2); 1 turns this off.
  // Other pixels take one ray: their texture is band-limited to the pixel footprint.
  int supersampling = 2;
  // Cylinder scene: angle in degrees travelled around the cylinder; above 360 the end of
  // the path overlaps its start.
  double cylinder_arc_degrees = 380.0;
  // Street scene: fraction of the route that is walked again after the full laps.
  double street_revisit_fraction = 0.1;
  // Street scene: full laps of the route before the revisit (2 with 0.3 walks 2.3 laps; 0
  // with 0.7 walks 70 % of the route and never comes back).
  int street_laps = 1;
  // Street scene: the buildings of each block are identical (one size, one material, the
  // texture anchored at each building's corner), so places far apart look the same.
  bool street_repeated_facades = false;
  // Street scene: "block" (around one block, counter-clockwise), "figure8" (around block A
  // counter-clockwise, then around its neighbour B clockwise, filming the block walked around),
  // "avenue" (straight east along the south side of a row of blocks like A with cross streets
  // between them, filming them, never coming back: laps and revisit only set the length, laps
  // + revisit times the loop around one block; no corners, so no abrupt turns) or "pan" (no
  // walk: standing in front of block A, the view turns 120 degrees on the spot, left to right;
  // laps and revisit do not apply).
  std::string street_route = "block";
  // Street scene: the view turned from the facade towards the walking direction, in degrees.
  double street_look_ahead_degrees = 0.0;
  // Street scene: the heading keeps the last side's direction until the corner, then jumps to
  // the next side's in one frame (instead of turning smoothly along the rounded corner).
  bool street_abrupt_turns = false;
  // Hand-held shake: standard deviation of a smooth random rotation about each camera axis,
  // in degrees (0: none). Part of the ground truth.
  double shake_degrees = 0.0;
  // Hand-held shake: standard deviation of a smooth random offset along each camera axis, in
  // centimetres (0: none). Part of the ground truth.
  double shake_centimeters = 0.0;
  // Degradations of the rendered frames (noise, blur, haze, dark frames, JPEG); none by default.
  FrameDegradationOptions degradation;
  // Write a single video.mp4 instead of images/frame_%06d.png.
  bool video = false;
  // Frame rate written into the video.
  int fps = 30;
  // Seed of the textures, the street layout, the shake and the sensor noise; the same seed
  // gives the same frames.
  uint64_t seed = kDefaultRandomSeed;

  // Throws InvalidArgument naming the offending field.
  void Check() const;
};

struct SyntheticScene {
  SynthOptions options;
  // The camera shared by all frames (MakeSynthCamera): PINHOLE unless options.lens says else.
  Camera camera;
  // Pose of every frame, camera-to-world.
  std::vector<Rigid3d> world_from_cam;
  SyntheticWorld world;
  // Street: world.boxes[0, num_block_buildings) are the buildings of the blocks the camera
  // walks around or along (then come pillars in front of them and the blocks across the
  // streets).
  int num_block_buildings = 0;

  int NumFrames() const { return static_cast<int>(world_from_cam.size()); }
};

// Builds the camera, the poses and the surfaces (cheap; renders nothing). Calls Check().
SyntheticScene MakeScene(const SynthOptions& options);

// "frame_%06d.png", the name of a frame in images/ and in groundtruth.txt; "frame_%06d.jpg" for
// images written as JPEG (options.degradation.jpeg_quality > 0 and no video).
std::string SyntheticFrameName(int frame);
std::string SyntheticFrameName(const SynthOptions& options, int frame);

// The ground truth as written to groundtruth.txt: one entry per frame, world_from_cam, named
// by SyntheticFrameName(scene.options, frame).
std::vector<TrajectoryEntry> GroundTruthTrajectory(const SyntheticScene& scene);

// The surface point seen through `image_point` (COLMAP image coordinates) of `frame`, with its
// distance from the camera centre, or nullopt where the ray sees the sky.
std::optional<SurfaceHit> CastPixelRay(const SyntheticScene& scene, int frame,
                                       const Eigen::Vector2d& image_point);

// Mean image motion in pixels per frame of the surfaces seen in `frame` (a grid of pixel rays
// projected into the neighbouring frame, the one whose view turned least; so at an abrupt turn
// it is the motion on the side that does not jump), or (0, 0) when nothing but sky is seen.
Eigen::Vector2d ImageMotion(const SyntheticScene& scene, int frame);

}  // namespace loopsfm
