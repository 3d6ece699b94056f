#pragma once
// The text formats of ../shared/data, used for input (intrinsics, ground truth) and output
// (trajectories, synthetic scenes):
//   intrinsics.txt   "PINHOLE w h fx fy cx cy" or "OPENCV w h fx fy cx cy k1 k2 p1 p2"
//                    (any COLMAP model name works); '#' starts a comment
//   trajectory       "name tx ty tz qx qy qz qw" per line, camera-to-world (world_from_cam)

#include <filesystem>
#include <string>
#include <vector>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/camera.h"

namespace loopsfm {

// Throws InputError naming the file and line when it cannot be parsed.
Camera ReadIntrinsicsFile(const std::filesystem::path& path);
void WriteIntrinsicsFile(const std::filesystem::path& path, const Camera& camera);

struct TrajectoryEntry {
  std::string name;
  Rigid3d world_from_cam;
};

std::vector<TrajectoryEntry> ReadTrajectoryFile(const std::filesystem::path& path);
void WriteTrajectoryFile(const std::filesystem::path& path,
                         const std::vector<TrajectoryEntry>& entries);

}  // namespace loopsfm
