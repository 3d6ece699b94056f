#include "loopsfm/scene/camera.h"

#include <algorithm>
#include <cmath>

#include <fmt/ranges.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {

Camera Camera::GuessFromImageSize(int width, int height, CameraModelId model_id) {
  Camera camera;
  camera.model_id = model_id;
  camera.width = width;
  camera.height = height;
  VisitCameraModel(model_id, [&](auto model) {
    using Model = decltype(model);
    camera.params.assign(Model::kNumParams, 0.0);
    camera.params[Model::kNumFocal] = width / 2.0;
    camera.params[Model::kNumFocal + 1] = height / 2.0;
  });
  camera.SetFocalLength(1.2 * std::max(width, height));
  camera.has_prior_focal_length = false;
  return camera;
}

void Camera::SetFocalLength(double focal_px) {
  VisitCameraModel(model_id, [&](auto model) {
    using Model = decltype(model);
    for (int i = 0; i < Model::kNumFocal; ++i) params.at(i) = focal_px;
  });
}

double Camera::MeanFocalLength() const {
  return VisitCameraModel(model_id, [&](auto model) {
    using Model = decltype(model);
    return Model::kNumFocal == 1 ? params[0] : 0.5 * (params[0] + params[1]);
  });
}

OpenCvIntrinsics Camera::ToOpenCv() const {
  const std::vector<double>& p = params;
  const auto perspective = [](double fx, double fy, double cx, double cy,
                              std::vector<double> coefficients) {
    coefficients.resize(8, 0.0);
    return OpenCvIntrinsics{fx, fy, cx, cy, std::move(coefficients), false};
  };
  const auto fisheye = [](double fx, double fy, double cx, double cy,
                          std::vector<double> coefficients) {
    coefficients.resize(4, 0.0);
    return OpenCvIntrinsics{fx, fy, cx, cy, std::move(coefficients), true};
  };
  switch (model_id) {
    case CameraModelId::kSimplePinhole:
      return perspective(p[0], p[0], p[1], p[2], {});
    case CameraModelId::kPinhole:
      return perspective(p[0], p[1], p[2], p[3], {});
    case CameraModelId::kSimpleRadial:
      return perspective(p[0], p[0], p[1], p[2], {p[3]});
    case CameraModelId::kRadial:
      return perspective(p[0], p[0], p[1], p[2], {p[3], p[4]});
    case CameraModelId::kOpenCV:
    case CameraModelId::kFullOpenCV:  // COLMAP's order after fx fy cx cy is OpenCV's
      return perspective(p[0], p[1], p[2], p[3], {p.begin() + 4, p.end()});
    case CameraModelId::kOpenCVFisheye:
      return fisheye(p[0], p[1], p[2], p[3], {p.begin() + 4, p.end()});
    case CameraModelId::kSimpleRadialFisheye:
      return fisheye(p[0], p[0], p[1], p[2], {p[3]});
    case CameraModelId::kRadialFisheye:
      return fisheye(p[0], p[0], p[1], p[2], {p[3], p[4]});
  }
  LOOPSFM_CHECK_MSG(false, "unhandled camera model {}", ModelName());
  return {};
}

Eigen::Vector2d Camera::CamFromImg(const Eigen::Vector2d& pixel) const {
  return VisitCameraModel(model_id, [&](auto model) {
    return decltype(model)::CamFromImg(params.data(), pixel.x(), pixel.y());
  });
}

Eigen::Vector2d Camera::ImgFromCam(const Eigen::Vector3d& p) const {
  return VisitCameraModel(model_id, [&](auto model) {
    Eigen::Vector2d xy;
    decltype(model)::ImgFromCam(params.data(), p.x(), p.y(), p.z(), &xy.x(), &xy.y());
    return xy;
  });
}

void Camera::Check() const {
  if (width <= 0 || height <= 0) {
    throw InputError(fmt::format("camera has invalid size {}x{}; width and height must be positive",
                                 width, height));
  }
  const int expected = CameraModelNumParams(model_id);
  if (static_cast<int>(params.size()) != expected) {
    throw InputError(fmt::format("camera model {} takes {} parameters ({}), got {}", ModelName(),
                                 expected,
                                 VisitCameraModel(model_id, [](auto m) {
                                   return decltype(m)::kParamsInfo;
                                 }),
                                 params.size()));
  }
  if (!std::all_of(params.begin(), params.end(), [](double p) { return std::isfinite(p); })) {
    throw InputError(fmt::format("camera parameters must be finite numbers, got {}",
                                 fmt::join(params, " ")));
  }
  if (!(MeanFocalLength() > 0)) {
    throw InputError(fmt::format("camera focal length must be positive, got {}", MeanFocalLength()));
  }
}

}  // namespace loopsfm
