#include "loopsfm/synth/lens.h"

#include <algorithm>
#include <array>
#include <string>
#include <utility>

#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

std::array<std::pair<std::string_view, double>, 8> Coefficients(const LensOptions& lens) {
  return {{{"k1", lens.k1}, {"k2", lens.k2}, {"k3", lens.k3}, {"k4", lens.k4},
           {"k5", lens.k5}, {"k6", lens.k6}, {"p1", lens.p1}, {"p2", lens.p2}}};
}

// The coefficient a model parameter name stands for ("k" is k1).
std::string_view CoefficientName(std::string_view param) { return param == "k" ? "k1" : param; }

// Checks that every pixel position of the image (a grid at most 4 pixels apart and the whole
// border, where the distortion is strongest) has an undistorted point that projects back onto
// it; the undistortion fails where the lens folds over or 90 degrees are reached.
void CheckInvertible(const Camera& camera) {
  const int step = 4;
  auto check = [&](double x, double y) {
    const bool inverted = VisitCameraModel(camera.model_id, [&](auto model) {
      Eigen::Vector2d uv;
      if (!decltype(model)::CamFromImgChecked(camera.params.data(), x, y, &uv)) return false;
      const Eigen::Vector3d ray(uv.x(), uv.y(), 1.0);
      return (camera.ImgFromCam(ray) - Eigen::Vector2d(x, y)).norm() <= 1e-6;
    });
    LOOPSFM_REQUIRE_OPTION(
        inverted,
        "the {} lens cannot be inverted at image point ({}, {}) of the {}x{} image: its "
        "distortion folds over inside the image (or, for a fisheye, reaches 90 degrees from "
        "the axis); use smaller distortion coefficients",
        camera.ModelName(), x, y, camera.width, camera.height);
  };
  for (int y = 0; y <= camera.height; ++y) {
    const bool border_row = y == 0 || y == camera.height;
    for (int x = 0; x <= camera.width; ++x) {
      const bool border = border_row || x == 0 || x == camera.width;
      if (border || (x % step == 0 && y % step == 0)) check(x, y);
    }
  }
}

}  // namespace

Camera MakeSynthCamera(const LensOptions& lens, int width, int height,
                       double focal_length_factor) {
  const std::vector<std::string_view> names = CameraModelParamNames(lens.model);
  for (const auto& [name, value] : Coefficients(lens)) {
    const bool taken = std::any_of(names.begin(), names.end(), [name = name](std::string_view p) {
      return CoefficientName(p) == name;
    });
    LOOPSFM_REQUIRE_OPTION(taken || value == 0.0,
                           "camera model {} does not take {} (its parameters: {}), got {} = {}",
                           CameraModelName(lens.model),
                           name, fmt::join(names, ", "), name, value);
  }
  Camera camera;
  camera.camera_id = 1;
  camera.model_id = lens.model;
  camera.width = width;
  camera.height = height;
  camera.has_prior_focal_length = true;
  const double focal = focal_length_factor * width;
  for (const std::string_view name : names) {
    if (name == "f" || name == "fx" || name == "fy") {
      camera.params.push_back(focal);
    } else if (name == "cx") {
      camera.params.push_back(0.5 * width);
    } else if (name == "cy") {
      camera.params.push_back(0.5 * height);
    } else {
      const auto coefficients = Coefficients(lens);
      const auto it = std::find_if(coefficients.begin(), coefficients.end(),
                                   [&](const auto& c) { return c.first == CoefficientName(name); });
      LOOPSFM_CHECK(it != coefficients.end());
      camera.params.push_back(it->second);
    }
  }
  LOOPSFM_CHECK_EQ(static_cast<int>(camera.params.size()), CameraModelNumParams(lens.model));
  const bool distorted = VisitCameraModel(lens.model, [](auto model) {
    return decltype(model)::kNumParams > decltype(model)::kNumFocalAndPP;
  });
  if (distorted) CheckInvertible(camera);
  return camera;
}

}  // namespace loopsfm
