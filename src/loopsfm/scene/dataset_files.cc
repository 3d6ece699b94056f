#include "loopsfm/scene/dataset_files.h"

#include <fstream>
#include <sstream>

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

}  // namespace

Camera ReadIntrinsicsFile(const std::filesystem::path& path) {
  std::ifstream in = OpenForReading(path, "intrinsics");
  std::optional<Camera> camera;
  ForEachDataLine(in, [&](int number, const std::string& line) {
    if (camera) return;
    std::istringstream fields(line);
    std::string model_name;
    Camera parsed;
    fields >> model_name >> parsed.width >> parsed.height;
    const auto model = CameraModelFromName(model_name);
    if (!model) {
      throw InputError(fmt::format(
          "{}:{}: unknown camera model '{}'; use PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL "
          "or OPENCV",
          path.string(), number, model_name));
    }
    parsed.model_id = *model;
    for (double value; fields >> value;) parsed.params.push_back(value);
    if (fields.fail() && !fields.eof()) {
      throw InputError(fmt::format("{}:{}: expected numbers after the model name, got '{}'",
                                   path.string(), number, line));
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
                                 "'PINHOLE 640 480 500 500 320 240'",
                                 path.string()));
  }
  return *camera;
}

void WriteIntrinsicsFile(const std::filesystem::path& path, const Camera& camera) {
  std::ofstream out(path);
  if (!out) throw StorageError(fmt::format("cannot write '{}'", path.string()));
  const auto info = VisitCameraModel(camera.model_id, [](auto m) { return decltype(m)::kParamsInfo; });
  out << "# " << camera.ModelName() << " width height " << info << "\n";
  out << camera.ModelName() << ' ' << camera.width << ' ' << camera.height;
  out.precision(9);
  for (double p : camera.params) out << ' ' << p;
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

}  // namespace loopsfm
