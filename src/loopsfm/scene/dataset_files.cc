#include "loopsfm/scene/dataset_files.h"

#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

std::ifstream OpenForReading(const std::filesystem::path& path, const char* what) {
  std::ifstream in(path);
  if (!in) {
    throw InputError(fmt::format("cannot read {} file '{}': check that it exists and is readable",
                                 what, path.string()));
  }
  return in;
}

// Calls f(line_number, line) for every non-empty line that is not a comment.
template <typename F>
void ForEachDataLine(std::istream& in, F&& f) {
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    f(number, line);
  }
}

// "'SIMPLE_PINHOLE width height f cx cy', 'PINHOLE width height fx fy cx cy', ...": the line
// of every camera model, for messages.
std::string IntrinsicsLineFormats() {
  std::string formats;
  for (const CameraModelId id : kCameraModelIds) {
    if (!formats.empty()) formats += ", ";
    formats += fmt::format("'{} width height {}'", CameraModelName(id),
                           fmt::join(CameraModelParamNames(id), " "));
  }
  return formats;
}

}  // namespace

Camera ReadIntrinsicsFile(const std::filesystem::path& path) {
  std::ifstream in = OpenForReading(path, "intrinsics");
  std::optional<Camera> camera;
  ForEachDataLine(in, [&](int number, const std::string& line) {
    if (camera) return;
    auto fail = [&](const std::string& what) {
      throw InputError(fmt::format("{}:{}: {}: '{}'; a camera line is 'MODEL width height "
                                   "PARAMS...', one of {}",
                                   path.string(), number, what, line, IntrinsicsLineFormats()));
    };
    std::istringstream fields(line);
    std::string model_name;
    Camera parsed;
    fields >> model_name;
    const auto model = CameraModelFromName(model_name);
    if (!model) fail(fmt::format("unknown camera model '{}'", model_name));
    parsed.model_id = *model;
    if (!(fields >> parsed.width >> parsed.height)) {
      fail(fmt::format("expected the image width and height after {}", model_name));
    }
    for (double value; fields >> value;) parsed.params.push_back(value);
    if (fields.fail() && !fields.eof()) fail("expected numbers after the image size");
    const int expected = CameraModelNumParams(parsed.model_id);
    if (static_cast<int>(parsed.params.size()) != expected) {
      fail(fmt::format("camera model {} takes {} parameters after the image size ({}), got {}",
                       model_name, expected, CameraModelParamsInfo(parsed.model_id),
                       parsed.params.size()));
    }
    parsed.has_prior_focal_length = true;
    try {
      parsed.Check();
    } catch (const InputError& e) {
      throw InputError(fmt::format("{}:{}: {}", path.string(), number, e.what()));
    }
    camera = parsed;
  });
  if (!camera) {
    throw InputError(fmt::format("intrinsics file '{}' holds no camera line; expected e.g. "
                                 "'PINHOLE 640 480 500 500 320 240', or one of {}",
                                 path.string(), IntrinsicsLineFormats()));
  }
  return *camera;
}

void WriteIntrinsicsFile(const std::filesystem::path& path, const Camera& camera) {
  std::ofstream out(path);
  if (!out) throw StorageError(fmt::format("cannot write '{}'", path.string()));
  out << "# " << camera.ModelName() << " width height " << CameraModelParamsInfo(camera.model_id)
      << "\n";
  out << camera.ModelName() << ' ' << camera.width << ' ' << camera.height;
  // The shortest decimal form that reads back as the same double.
  for (double p : camera.params) out << fmt::format(" {}", p);
  out << '\n';
}

std::vector<TrajectoryEntry> ReadTrajectoryFile(const std::filesystem::path& path) {
  std::ifstream in = OpenForReading(path, "trajectory");
  std::vector<TrajectoryEntry> entries;
  ForEachDataLine(in, [&](int number, const std::string& line) {
    std::istringstream fields(line);
    TrajectoryEntry entry;
    double tx, ty, tz, qx, qy, qz, qw;
    if (!(fields >> entry.name >> tx >> ty >> tz >> qx >> qy >> qz >> qw)) {
      throw InputError(fmt::format("{}:{}: expected 'name tx ty tz qx qy qz qw', got '{}'",
                                   path.string(), number, line));
    }
    const Eigen::Quaterniond q(qw, qx, qy, qz);
    if (std::abs(q.norm() - 1.0) > 1e-3) {
      throw InputError(fmt::format("{}:{}: quaternion is not unit length (norm {})", path.string(),
                                   number, q.norm()));
    }
    entry.world_from_cam = Rigid3d(q.normalized(), Eigen::Vector3d(tx, ty, tz));
    entries.push_back(std::move(entry));
  });
  return entries;
}

void WriteTrajectoryFile(const std::filesystem::path& path,
                         const std::vector<TrajectoryEntry>& entries) {
  std::ofstream out(path);
  if (!out) throw StorageError(fmt::format("cannot write '{}'", path.string()));
  out << "# name tx ty tz qx qy qz qw   (camera-to-world; OpenCV camera axes: x right, y down, "
         "z forward)\n";
  for (const auto& e : entries) {
    const auto& t = e.world_from_cam.translation;
    const auto& q = e.world_from_cam.rotation;
    out << fmt::format("{} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f}\n", e.name, t.x(),
                       t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
  }
}

std::vector<LoopLink> ReadLoopLinksFile(const std::filesystem::path& path) {
  std::ifstream in = OpenForReading(path, "loop links");
  std::vector<LoopLink> links;
  ForEachDataLine(in, [&](int number, const std::string& line) {
    std::istringstream fields(line);
    LoopLink link;
    std::string rest;
    if (!(fields >> link.method >> link.old_frame >> link.recent_frame >> link.num_point_pairs) ||
        (fields >> rest) || link.num_point_pairs < 0 ||
        (link.method != "posegraph" && link.method != "split")) {
      throw InputError(fmt::format(
          "{}:{}: expected 'method old_frame recent_frame point_pairs' (method posegraph or "
          "split, point_pairs a count), got '{}'", path.string(),
          number, line));
    }
    links.push_back(std::move(link));
  });
  return links;
}

void WriteLoopLinksFile(const std::filesystem::path& path, const std::vector<LoopLink>& links) {
  std::ofstream out(path);
  out << "# method old_frame recent_frame point_pairs   (frames far apart in time that loop "
         "closing tied together)\n";
  for (const LoopLink& link : links) {
    out << link.method << ' ' << link.old_frame << ' ' << link.recent_frame << ' '
        << link.num_point_pairs << '\n';
  }
  if (!out) throw StorageError(fmt::format("cannot write '{}'", path.string()));
}

}  // namespace loopsfm
