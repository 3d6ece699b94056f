#pragma once
// COLMAP 3.8 sparse model folders: cameras, images and points3D, in COLMAP's binary
// (.bin) and text (.txt) formats, so `colmap gui`, `colmap model_converter` and pycolmap
// read what loopsfm writes, and loopsfm can score a model that COLMAP wrote.
//
// Binary layout (little-endian, no padding):
//   cameras.bin   uint64 num_cameras, then per camera:
//                   uint32 camera_id, int32 model_id, uint64 width, uint64 height,
//                   double params[num_params(model)]
//   images.bin    uint64 num_reg_images, then per registered image:
//                   uint32 image_id, double qw qx qy qz, double tx ty tz (cam_from_world),
//                   uint32 camera_id, name bytes + '\0', uint64 num_points2D,
//                   per point2D: double x, double y, uint64 point3D_id (2^64-1 for none)
//   points3D.bin  uint64 num_points, then per point:
//                   uint64 point3D_id, double x y z, uint8 r g b, double error,
//                   uint64 track_length, per element: uint32 image_id, uint32 point2D_idx
// Text layout: the same fields, one camera / one 3D point per line and two lines per
// image (the pose line, then "x y point3D_id ..." with -1 for none); '#' starts a comment.
//
// Writing: only registered images are written (as COLMAP does); cameras, images and points
// are written in id order; track elements of unregistered images are left out. Image names
// with whitespace cannot be written as text (COLMAP splits the line at spaces).
// Reading: images are registered; 3D point ids are renumbered 1..N in the order of the
// file's ids (so ids 1..N are kept); which 3D point an image's 2D point observes is taken
// from the point tracks (points3D), the ids in the images file are not used. Camera
// models not in sensor/camera_models.h (COLMAP's FOV and thin-prism models) are rejected.

#include <filesystem>

#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

// Writes cameras.bin, images.bin and points3D.bin into `dir` (created when missing).
// Throws StorageError when a file cannot be written.
void WriteColmapModelBinary(const std::filesystem::path& dir, const Reconstruction& reconstruction);

// Writes cameras.txt, images.txt and points3D.txt into `dir` (created when missing).
// Throws StorageError when a file cannot be written or an image name holds whitespace.
void WriteColmapModelText(const std::filesystem::path& dir, const Reconstruction& reconstruction);

// Read a model folder. Throw InputError naming the file (and line, for text) when a file is
// missing, truncated, inconsistent (unknown camera or image ids, observations out of
// range) or otherwise not a COLMAP model.
Reconstruction ReadColmapModelBinary(const std::filesystem::path& dir);
Reconstruction ReadColmapModelText(const std::filesystem::path& dir);

// Reads the binary model when `dir` holds cameras.bin, else the text model.
Reconstruction ReadColmapModel(const std::filesystem::path& dir);

}  // namespace loopsfm
