#include "loopsfm/report/report_data.h"

#include <algorithm>
#include <fstream>
#include <iterator>
#include <map>

#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {

nlohmann::json ReportCameras(const Reconstruction& model) {
  const std::map<camera_t, Camera> sorted(model.Cameras().begin(), model.Cameras().end());
  nlohmann::json cameras = nlohmann::json::array();
  for (const auto& [id, camera] : sorted) {
    const Eigen::Vector2d principal = camera.ImgFromCam(Eigen::Vector3d::UnitZ());
    cameras.push_back({{"camera_id", id}, {"model", camera.ModelName()}, {"width", camera.width},
                       {"height", camera.height}, {"params", camera.params},
                       {"focal_px", camera.MeanFocalLength()}, {"cx", principal.x()},
                       {"cy", principal.y()}});
  }
  return cameras;
}

nlohmann::json ReportFrames(const std::vector<Frame>& frames, const std::vector<Reconstruction>& models) {
  nlohmann::json list = nlohmann::json::array();
  for (size_t i = 0; i < frames.size(); ++i) {
    nlohmann::json entry = {{"index", i}, {"name", frames[i].name}, {"registered", false}};
    for (size_t k = 0; k < models.size(); ++k) {
      const Reconstruction& model = models[k];
      if (!model.ExistsImage(frames[i].image_id) || !model.IsRegistered(frames[i].image_id)) continue;
      const Image& image = model.GetImage(frames[i].image_id);
      const Eigen::Matrix3d r = image.cam_from_world.rotation.toRotationMatrix().transpose();
      const Eigen::Vector3d c = image.ProjectionCenter();
      entry["registered"] = true;
      entry["model"] = k;
      entry["camera_id"] = image.camera_id;
      entry["num_points2D"] = image.points2D.size();
      entry["num_points3D"] = image.num_points3D;
      entry["center"] = {c.x(), c.y(), c.z()};
      entry["world_from_cam_rotation"] = {r(0, 0), r(0, 1), r(0, 2), r(1, 0), r(1, 1),
                                          r(1, 2), r(2, 0), r(2, 1), r(2, 2)};
      break;
    }
    list.push_back(std::move(entry));
  }
  return list;
}

nlohmann::json ReportPoints(const Reconstruction& model, size_t max_points) {
  std::vector<point3D_t> ids;
  ids.reserve(model.NumPoints3D());
  for (const auto& [id, point] : model.Points3D()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  const size_t step = max_points == 0 ? ids.size() + 1 : (ids.size() + max_points - 1) / max_points;
  std::vector<double> xyz;
  std::vector<int> rgb;
  for (size_t i = 0; i < ids.size(); i += std::max<size_t>(step, 1)) {
    const Point3D& point = model.GetPoint3D(ids[i]);
    xyz.insert(xyz.end(), {point.xyz.x(), point.xyz.y(), point.xyz.z()});
    rgb.insert(rgb.end(), {point.color[0], point.color[1], point.color[2]});
  }
  return {{"xyz", xyz}, {"rgb", rgb}};
}

nlohmann::json ReportTopViewPath(const std::string& label, const std::vector<Eigen::Vector3d>& centres,
                                 const TopViewPlane& plane) {
  nlohmann::json xy = nlohmann::json::array();
  for (const Eigen::Vector3d& c : centres) {
    const Eigen::Vector2d p = plane.Project(c);
    xy.push_back({p.x(), p.y()});
  }
  return {{"label", label}, {"xy", xy}};
}

nlohmann::json ReportTopViewLinks(const std::vector<LoopLink>& links,
                                  const std::map<std::string, Eigen::Vector3d>& centres,
                                  const TopViewPlane& plane) {
  nlohmann::json groups = nlohmann::json::array();
  std::map<std::string, size_t> group_of;
  for (const LoopLink& link : links) {
    const auto old_it = centres.find(link.old_frame);
    const auto recent_it = centres.find(link.recent_frame);
    if (old_it == centres.end() || recent_it == centres.end()) continue;
    const auto [it, added] = group_of.emplace(link.method, groups.size());
    if (added) {
      groups.push_back({{"method", link.method}, {"segments", nlohmann::json::array()}});
    }
    const Eigen::Vector2d a = plane.Project(old_it->second), b = plane.Project(recent_it->second);
    groups[it->second]["segments"].push_back({a.x(), a.y(), b.x(), b.y()});
  }
  for (nlohmann::json& group : groups) {
    group["label"] = fmt::format("loop links ({}): {}", group["method"].get<std::string>(),
                                 group["segments"].size());
  }
  return groups;
}

nlohmann::json ReportImage(const std::string& title, const std::filesystem::path& png) {
  std::ifstream in(png, std::ios::binary);
  const std::string bytes = in ? std::string(std::istreambuf_iterator<char>(in), {}) : std::string();
  if (bytes.empty()) {
    throw InputError(fmt::format("report: cannot read the image '{}'", png.string()));
  }
  return {{"title", title}, {"png_base64", Base64Encode(bytes)}};
}

std::string Base64Encode(std::string_view bytes) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = (uint8_t(bytes[i]) << 16) | (uint8_t(bytes[i + 1]) << 8) | uint8_t(bytes[i + 2]);
    out += {kAlphabet[v >> 18], kAlphabet[(v >> 12) & 63], kAlphabet[(v >> 6) & 63], kAlphabet[v & 63]};
  }
  if (i < bytes.size()) {
    const bool two = i + 1 < bytes.size();
    const uint32_t v = (uint8_t(bytes[i]) << 16) | (two ? uint8_t(bytes[i + 1]) << 8 : 0);
    out += {kAlphabet[v >> 18], kAlphabet[(v >> 12) & 63], two ? kAlphabet[(v >> 6) & 63] : '=', '='};
  }
  return out;
}

}  // namespace loopsfm
