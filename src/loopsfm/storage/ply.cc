#include "loopsfm/storage/ply.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <fstream>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Appends the little-endian bytes of a value.
template <typename T>
void AppendLittleEndian(T value, std::string* out) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
  out->append(bytes, sizeof(T));
}

}  // namespace

void WritePly(const std::filesystem::path& path, const Reconstruction& reconstruction,
              const PlyOptions& options) {
  options.Check();
  if (path.has_parent_path()) {
    std::error_code ec;
    std::filesystem::create_directories(path.parent_path(), ec);
  }
  std::ofstream out(path, std::ios::binary);
  if (!out) {
    throw StorageError(
        fmt::format("cannot write '{}': check that the folder is writable", path.string()));
  }
  std::vector<point3D_t> ids;
  for (const auto& [id, point] : reconstruction.Points3D()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());

  const char* type = options.double_precision ? "double" : "float";
  out << "ply\n"
      << "format binary_little_endian 1.0\n"
      << "comment written by loopsfm\n"
      << "element vertex " << ids.size() << "\n"
      << "property " << type << " x\n"
      << "property " << type << " y\n"
      << "property " << type << " z\n"
      << "property uchar red\n"
      << "property uchar green\n"
      << "property uchar blue\n"
      << "end_header\n";
  std::string data;
  data.reserve(ids.size() * (options.double_precision ? 27 : 15));
  for (point3D_t id : ids) {
    const Point3D& point = reconstruction.GetPoint3D(id);
    for (int k = 0; k < 3; ++k) {
      if (options.double_precision) {
        AppendLittleEndian<double>(point.xyz(k), &data);
      } else {
        AppendLittleEndian<float>(static_cast<float>(point.xyz(k)), &data);
      }
    }
    for (int k = 0; k < 3; ++k) AppendLittleEndian<uint8_t>(point.color(k), &data);
  }
  out.write(data.data(), static_cast<std::streamsize>(data.size()));
  out.close();
  if (!out) throw StorageError(fmt::format("writing '{}' failed (disk full?)", path.string()));
}

}  // namespace loopsfm
