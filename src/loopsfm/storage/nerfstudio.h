#pragma once
// nerfstudio's transforms.json (what `ns-process-data` writes and its nerfstudio data parser
// reads), from a reconstruction:
//   { "w", "h", "fl_x", "fl_y", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2",
//     "camera_model": "OPENCV" | "OPENCV_FISHEYE",
//     "frames": [ { "file_path": "images/NAME", "transform_matrix": 4x4, "colmap_im_id" } ],
//     "ply_file_path": "points.ply" }
// transform_matrix is camera-to-world with OpenGL camera axes (x right, y up, z back): the
// model's world_from_cam with its y and z axes negated. World coordinates are the model's
// own, so the PLY written beside it lines up. Intrinsics sit at the top level when every
// registered frame shares one camera, else in each frame. Principal points move from COLMAP's
// pixel convention (top-left pixel centre at 0.5) to nerfstudio's, which is the same: the
// numbers are written unchanged.

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

struct NerfstudioOptions {
  // Folder of the frames, relative to transforms.json; frames are "<images_dir>/<name>".
  std::string images_dir = "images";
  // The point cloud, relative to transforms.json; empty: no ply_file_path.
  std::string ply_file_path = "points.ply";
  void Check() const;
};

// nerfstudio's intrinsics fields for one camera. Throws InvalidArgument for a camera that
// nerfstudio's OPENCV / OPENCV_FISHEYE models cannot express (FULL_OPENCV with k4..k6 set).
nlohmann::json NerfstudioIntrinsics(const Camera& camera);

// The registered images of `reconstruction`, in name order. Throws InvalidArgument when
// nothing is registered.
nlohmann::json NerfstudioTransforms(const Reconstruction& reconstruction,
                                    const NerfstudioOptions& options = {});

// Writes transforms (NerfstudioTransforms) to `path`; throws StorageError when it cannot be
// written.
void WriteNerfstudioTransforms(const std::filesystem::path& path, const nlohmann::json& transforms);

}  // namespace loopsfm
