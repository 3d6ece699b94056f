#pragma once
// The text formats of ../shared/data, used for input (intrinsics, ground truth) and output
// (trajectories, synthetic scenes):
//   intrinsics.txt   "MODEL w h PARAMS..." with a COLMAP camera model and its parameters in
//                    COLMAP's order, e.g. "PINHOLE w h fx fy cx cy", "OPENCV w h fx fy cx cy
//                    k1 k2 p1 p2", "OPENCV_FISHEYE w h fx fy cx cy k1 k2 k3 k4" (every model
//                    of sensor/camera_models.h); '#' starts a comment
//   trajectory       "name tx ty tz qx qy qz qw" per line, camera-to-world (world_from_cam)

#include <filesystem>
#include <string>
#include <vector>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/camera.h"

namespace loopsfm {

// The first camera line of the file. Throws InputError naming the file and line, what was
// expected and the line of every model, when it cannot be parsed (unknown model, wrong number
// of parameters, bad numbers).
Camera ReadIntrinsicsFile(const std::filesystem::path& path);
// Writes a comment naming the parameters, then the camera line, each number in the shortest
// form that reads back as the same double.
void WriteIntrinsicsFile(const std::filesystem::path& path, const Camera& camera);

struct TrajectoryEntry {
  std::string name;
  Rigid3d world_from_cam;
};

std::vector<TrajectoryEntry> ReadTrajectoryFile(const std::filesystem::path& path);
void WriteTrajectoryFile(const std::filesystem::path& path,
                         const std::vector<TrajectoryEntry>& entries);

}  // namespace loopsfm
