#include "loopsfm/storage/nerfstudio.h"

#include <algorithm>
#include <fstream>

#include "loopsfm/util/errors.h"

namespace loopsfm {

void NerfstudioOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(!images_dir.empty(), "the nerfstudio images folder must be named");
}

nlohmann::json NerfstudioIntrinsics(const Camera& camera) {
  const OpenCvIntrinsics o = camera.ToOpenCv();
  const std::vector<double>& d = o.distortion;
  nlohmann::json j = {{"w", camera.width}, {"h", camera.height}, {"fl_x", o.fx},
                      {"fl_y", o.fy},      {"cx", o.cx},         {"cy", o.cy}};
  if (o.fisheye) {
    j.update({{"camera_model", "OPENCV_FISHEYE"}, {"k1", d[0]}, {"k2", d[1]}, {"k3", d[2]},
              {"k4", d[3]}});
  } else {
    // nerfstudio's OPENCV holds k1..k3, p1, p2: not FULL_OPENCV's rational k4..k6.
    if (d[5] != 0.0 || d[6] != 0.0 || d[7] != 0.0) {
      throw InvalidArgument(fmt::format(
          "transforms.json cannot hold camera {}'s FULL_OPENCV rational distortion (k4..k6 = "
          "{}, {}, {}); export the undistorted layout instead (--export gsplat), or map with "
          "--camera-model OPENCV",
          camera.camera_id, d[5], d[6], d[7]));
    }
    j.update({{"camera_model", "OPENCV"}, {"k1", d[0]}, {"k2", d[1]}, {"k3", d[4]}, {"k4", 0.0},
              {"p1", d[2]}, {"p2", d[3]}});
  }
  return j;
}

nlohmann::json NerfstudioTransforms(const Reconstruction& reconstruction,
                                    const NerfstudioOptions& options) {
  options.Check();
  std::vector<const Image*> images;
  for (image_t id : reconstruction.RegImageIds()) images.push_back(&reconstruction.GetImage(id));
  if (images.empty()) {
    throw InvalidArgument("transforms.json needs a model with registered frames; this one has none");
  }
  std::sort(images.begin(), images.end(),
            [](const Image* a, const Image* b) { return a->name < b->name; });
  const bool one_camera =
      std::all_of(images.begin(), images.end(),
                  [&](const Image* image) { return image->camera_id == images[0]->camera_id; });

  nlohmann::json transforms = nlohmann::json::object();
  if (one_camera) {
    transforms = NerfstudioIntrinsics(reconstruction.GetCamera(images[0]->camera_id));
  }
  nlohmann::json frames = nlohmann::json::array();
  for (const Image* image : images) {
    // world_from_cam, then OpenCV camera axes (y down, z forward) to OpenGL (y up, z back).
    Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
    c2w.topLeftCorner<3, 4>() = image->cam_from_world.Inverse().ToMatrix();
    c2w.topRows<3>().col(1) *= -1.0;
    c2w.topRows<3>().col(2) *= -1.0;
    nlohmann::json rows = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
    nlohmann::json frame = {{"file_path", options.images_dir + "/" + image->name},
                            {"transform_matrix", rows},
                            {"colmap_im_id", image->image_id}};
    if (!one_camera) frame.update(NerfstudioIntrinsics(reconstruction.GetCamera(image->camera_id)));
    frames.push_back(std::move(frame));
  }
  transforms["frames"] = std::move(frames);
  if (!options.ply_file_path.empty()) transforms["ply_file_path"] = options.ply_file_path;
  return transforms;
}

void WriteNerfstudioTransforms(const std::filesystem::path& path, const nlohmann::json& transforms) {
  std::ofstream out(path);
  out << transforms.dump(2) << "\n";
  if (!out) {
    throw StorageError(
        fmt::format("cannot write '{}': check that the folder is writable", path.string()));
  }
}

}  // namespace loopsfm
