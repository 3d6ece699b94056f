#include "loopsfm/sensor/camera_models.h"

namespace loopsfm {

std::string_view CameraModelName(CameraModelId id) {
  return VisitCameraModel(id, [](auto model) { return decltype(model)::kName; });
}

int CameraModelNumParams(CameraModelId id) {
  return VisitCameraModel(id, [](auto model) { return decltype(model)::kNumParams; });
}

std::optional<CameraModelId> CameraModelFromName(std::string_view name) {
  for (int id = 0; id <= 4; ++id) {
    if (CameraModelName(static_cast<CameraModelId>(id)) == name) {
      return static_cast<CameraModelId>(id);
    }
  }
  return std::nullopt;
}

}  // namespace loopsfm
