#pragma once
// Example cameras shared by the camera model tests: a 640 x 480 image with a focal length of
// about 500 pixels and distortion of the strength seen in real lenses.

#include <vector>

#include "loopsfm/sensor/camera_models.h"

namespace loopsfm::camera_models_test {

inline constexpr double kImageWidth = 640.0;
inline constexpr double kImageHeight = 480.0;

inline std::vector<double> ExampleParams(CameraModelId id) {
  switch (id) {
    case CameraModelId::kSimplePinhole: return {500, 320, 240};
    case CameraModelId::kPinhole: return {500, 510, 320, 240};
    case CameraModelId::kSimpleRadial: return {500, 320, 240, -0.08};
    case CameraModelId::kRadial: return {500, 320, 240, -0.08, 0.01};
    case CameraModelId::kOpenCV: return {500, 510, 320, 240, 0.0578, -0.0805, -0.00098, 0.00016};
    case CameraModelId::kOpenCVFisheye: return {500, 510, 330, 235, 0.05, -0.02, 0.004, -0.0008};
    case CameraModelId::kFullOpenCV:
      return {500, 510, 320, 240, 0.0578, -0.0805, -0.00098, 0.00016, 0.012, 0.03, -0.01, 0.004};
    case CameraModelId::kSimpleRadialFisheye: return {500, 320, 240, 0.03};
    case CameraModelId::kRadialFisheye: return {500, 325, 236, 0.03, -0.005};
  }
  return {};
}

}  // namespace loopsfm::camera_models_test
