#pragma once
// The text formats of ../shared/data, used for input (intrinsics, ground truth) and output
// (trajectories, synthetic scenes):
//   intrinsics.txt   "MODEL w h PARAMS..." with a COLMAP camera model and its parameters in
//                    COLMAP's order, e.g. "PINHOLE w h fx fy cx cy", "OPENCV w h fx fy cx cy
//                    k1 k2 p1 p2", "OPENCV_FISHEYE w h fx fy cx cy k1 k2 k3 k4" (every model
//                    of sensor/camera_models.h); '#' starts a comment
//   trajectory       "name tx ty tz qx qy qz qw" per line, camera-to-world (world_from_cam)
//   loop links       "method old_frame recent_frame point_pairs" per line: two frames far apart
//                    in time that loop closing tied together (OUT/loop_links.txt)

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

// Two frames far apart in time that loop closing tied together, and the point pairs behind
// the link; method: "posegraph" or "split" (the --loop-closing method that made it).
struct LoopLink {
  std::string method;
  std::string old_frame, recent_frame;
  int num_point_pairs = 0;
};

std::vector<LoopLink> ReadLoopLinksFile(const std::filesystem::path& path);
void WriteLoopLinksFile(const std::filesystem::path& path, const std::vector<LoopLink>& links);

}  // namespace loopsfm
