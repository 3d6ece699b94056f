#pragma once
// PLY export of a reconstruction's 3D points, for MeshLab, CloudCompare, Open3D, Blender:
//   ply
//   format binary_little_endian 1.0
//   element vertex N
//   property float x / y / z          (double with PlyOptions::double_precision)
//   property uchar red / green / blue
//   end_header
// followed by N packed records, points in id order.

#include <filesystem>

#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

struct PlyOptions {
  // Positions as 64-bit doubles instead of 32-bit floats (floats are what every viewer
  // reads; doubles keep precision for georeferenced coordinates far from the origin).
  bool double_precision = false;
  void Check() const {}  // every combination is valid
};

// Writes the 3D points of `reconstruction` to `path` (parent folder created when missing).
// Throws StorageError when the file cannot be written.
void WritePly(const std::filesystem::path& path, const Reconstruction& reconstruction,
              const PlyOptions& options = {});

}  // namespace loopsfm
