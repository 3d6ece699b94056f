#include "loopsfm/storage/nerfstudio.h"

#include <algorithm>
#include <fstream>

#include "loopsfm/util/errors.h"

namespace loopsfm {

void NerfstudioOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(!images_dir.empty(), "the nerfstudio images folder must be named");
}

nlohmann::json NerfstudioIntrinsics(const Camera& camera) {
  const std::vector<double>& p = camera.params;
  nlohmann::json j = {{"w", camera.width}, {"h", camera.height}};
  auto set_pinhole = [&](double fx, double fy, double cx, double cy) {
    j["fl_x"] = fx;
    j["fl_y"] = fy;
    j["cx"] = cx;
    j["cy"] = cy;
  };
  auto set_distortion = [&](const char* model, double k1, double k2, double k3, double k4,
                            double p1, double p2) {
    j["camera_model"] = model;
    j["k1"] = k1;
    j["k2"] = k2;
    j["k3"] = k3;
    j["k4"] = k4;
    j["p1"] = p1;
    j["p2"] = p2;
  };
  switch (camera.model_id) {
    case CameraModelId::kSimplePinhole:
      set_pinhole(p[0], p[0], p[1], p[2]);
      set_distortion("OPENCV", 0, 0, 0, 0, 0, 0);
      break;
    case CameraModelId::kPinhole:
      set_pinhole(p[0], p[1], p[2], p[3]);
      set_distortion("OPENCV", 0, 0, 0, 0, 0, 0);
      break;
    case CameraModelId::kSimpleRadial:
      set_pinhole(p[0], p[0], p[1], p[2]);
      set_distortion("OPENCV", p[3], 0, 0, 0, 0, 0);
      break;
    case CameraModelId::kRadial:
      set_pinhole(p[0], p[0], p[1], p[2]);
      set_distortion("OPENCV", p[3], p[4], 0, 0, 0, 0);
      break;
    case CameraModelId::kOpenCV:
      set_pinhole(p[0], p[1], p[2], p[3]);
      set_distortion("OPENCV", p[4], p[5], 0, 0, p[6], p[7]);
      break;
    case CameraModelId::kFullOpenCV:
      // fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6: nerfstudio's OPENCV holds k1..k3, p1, p2 only.
      if (p[9] != 0.0 || p[10] != 0.0 || p[11] != 0.0) {
        throw InvalidArgument(fmt::format(
            "transforms.json cannot hold camera {}'s FULL_OPENCV rational distortion (k4..k6 = "
            "{}, {}, {}); export the undistorted layout instead (--export gsplat), or map with "
            "--camera-model OPENCV",
            camera.camera_id, p[9], p[10], p[11]));
      }
      set_pinhole(p[0], p[1], p[2], p[3]);
      set_distortion("OPENCV", p[4], p[5], p[8], 0, p[6], p[7]);
      break;
    case CameraModelId::kOpenCVFisheye:
      set_pinhole(p[0], p[1], p[2], p[3]);
      set_distortion("OPENCV_FISHEYE", p[4], p[5], p[6], p[7], 0, 0);
      break;
    case CameraModelId::kSimpleRadialFisheye:
      set_pinhole(p[0], p[0], p[1], p[2]);
      set_distortion("OPENCV_FISHEYE", p[3], 0, 0, 0, 0, 0);
      break;
    case CameraModelId::kRadialFisheye:
      set_pinhole(p[0], p[0], p[1], p[2]);
      set_distortion("OPENCV_FISHEYE", p[3], p[4], 0, 0, 0, 0);
      break;
  }
  if (j["camera_model"] == "OPENCV_FISHEYE") {
    j.erase("p1");
    j.erase("p2");
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

void WriteNerfstudioTransforms(const std::filesystem::path& path,
                               const Reconstruction& reconstruction,
                               const NerfstudioOptions& options) {
  const nlohmann::json transforms = NerfstudioTransforms(reconstruction, options);
  std::ofstream out(path);
  out << transforms.dump(2) << "\n";
  if (!out) {
    throw StorageError(
        fmt::format("cannot write '{}': check that the folder is writable", path.string()));
  }
}

}  // namespace loopsfm
