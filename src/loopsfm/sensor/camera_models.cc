#include "loopsfm/sensor/camera_models.h"

#include <algorithm>

#include "loopsfm/util/errors.h"

namespace loopsfm {

bool IsKnownCameraModel(int id) {
  return std::any_of(kCameraModelIds.begin(), kCameraModelIds.end(),
                     [id](CameraModelId known) { return static_cast<int>(known) == id; });
}

std::string_view CameraModelName(CameraModelId id) {
  return VisitCameraModel(id, [](auto model) { return decltype(model)::kName; });
}

int CameraModelNumParams(CameraModelId id) {
  return VisitCameraModel(id, [](auto model) { return decltype(model)::kNumParams; });
}

std::string_view CameraModelParamsInfo(CameraModelId id) {
  return VisitCameraModel(id, [](auto model) { return decltype(model)::kParamsInfo; });
}

std::vector<std::string_view> CameraModelParamNames(CameraModelId id) {
  const std::string_view info = CameraModelParamsInfo(id);
  std::vector<std::string_view> names;
  for (size_t begin = 0; begin < info.size();) {
    const size_t end = std::min(info.find(',', begin), info.size());
    names.push_back(info.substr(begin, end - begin));
    begin = info.find_first_not_of(' ', end + 1);
  }
  return names;
}

std::string CameraModelNameList() {
  std::string list;
  for (const CameraModelId id : kCameraModelIds) {
    if (!list.empty()) list += ", ";
    list += CameraModelName(id);
  }
  return list;
}

std::optional<CameraModelId> CameraModelFromName(std::string_view name) {
  for (const CameraModelId id : kCameraModelIds) {
    if (CameraModelName(id) == name) return id;
  }
  return std::nullopt;
}

CameraModelId ParseCameraModel(std::string_view name) {
  const std::optional<CameraModelId> id = CameraModelFromName(name);
  if (!id) {
    throw InvalidArgument(fmt::format("unknown camera model '{}'; use one of {}", name,
                                      CameraModelNameList()));
  }
  return *id;
}

}  // namespace loopsfm
