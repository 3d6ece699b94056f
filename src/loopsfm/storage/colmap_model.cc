#include "loopsfm/storage/colmap_model.h"

#include <cstring>
#include <fstream>
#include <string_view>

#include "loopsfm/storage/colmap_model_internal.h"
#include "loopsfm/util/endian.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;
using colmap_model_internal::FinishWriting;
using colmap_model_internal::ModelBuilder;
using colmap_model_internal::OpenForWriting;
using colmap_model_internal::SortedCameraIds;
using colmap_model_internal::SortedPoint3DIds;
using colmap_model_internal::WrittenElements;
using colmap_model_internal::WrittenPoint3DId;

class BinaryWriter {
 public:
  BinaryWriter(const fs::path& dir, const char* name)
      : path_(dir / name), out_(OpenForWriting(dir, name, /*binary=*/true)) {}
  template <typename T>
  void Write(T value) {
    value = ToFromLittleEndian(value);
    out_.write(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  void WriteString(const std::string& s) { out_.write(s.c_str(), s.size() + 1); }
  void Finish() { FinishWriting(out_, path_); }

 private:
  fs::path path_;
  std::ofstream out_;
};

class BinaryReader {
 public:
  BinaryReader(const fs::path& dir, const char* name) : path_(dir / name) {
    std::error_code ec;
    size_ = fs::file_size(path_, ec);
    in_.open(path_, std::ios::binary);
    if (ec || !in_) {
      throw InputError(
          fmt::format("cannot read '{}': a COLMAP binary model folder holds "
                      "cameras.bin, images.bin and points3D.bin",
                      path_.string()));
    }
  }
  std::string Where() const { return fmt::format("'{}'", path_.string()); }

  template <typename T>
  T Read(std::string_view what) {
    T value;
    if (!in_.read(reinterpret_cast<char*>(&value), sizeof(T))) Truncated(what);
    pos_ += sizeof(T);
    return ToFromLittleEndian(value);
  }
  std::string ReadString(std::string_view what) {
    std::string s;
    for (char c; (c = Read<char>(what)) != '\0';) s.push_back(c);
    return s;
  }
  // A record count, checked against the bytes left so a corrupt count fails cleanly.
  uint64_t ReadCount(std::string_view what, uint64_t min_bytes_each) {
    const uint64_t count = Read<uint64_t>(what);
    if (min_bytes_each > 0 && count > (size_ - pos_) / min_bytes_each) {
      throw InputError(fmt::format("{} is corrupt: it claims {} {} but has only {} bytes left",
                                   Where(), count, what, size_ - pos_));
    }
    return count;
  }
  void ExpectEnd() {
    if (pos_ != size_) {
      throw InputError(fmt::format("{} is corrupt: {} unexpected bytes after the last record",
                                   Where(), size_ - pos_));
    }
  }

 private:
  [[noreturn]] void Truncated(std::string_view what) {
    throw InputError(
        fmt::format("{} ends early while reading {}: the file is truncated or not "
                    "a COLMAP 3.8 binary model",
                    Where(), what));
  }
  fs::path path_;
  std::ifstream in_;
  uint64_t size_ = 0;
  uint64_t pos_ = 0;
};

void ReadCamerasBinary(const fs::path& dir, ModelBuilder* builder) {
  BinaryReader in(dir, "cameras.bin");
  const uint64_t num_cameras = in.ReadCount("cameras", 24);
  for (uint64_t i = 0; i < num_cameras; ++i) {
    Camera camera;
    camera.camera_id = in.Read<uint32_t>("camera id");
    const int model_id = in.Read<int32_t>("camera model id");
    if (!IsKnownCameraModel(model_id)) {
      throw InputError(
          fmt::format("{}: camera {} uses COLMAP camera model id {}, which loopsfm "
                      "does not support (supported: {})",
                      in.Where(), camera.camera_id, model_id, CameraModelNameList()));
    }
    camera.model_id = static_cast<CameraModelId>(model_id);
    const uint64_t width = in.Read<uint64_t>("camera width");
    const uint64_t height = in.Read<uint64_t>("camera height");
    if (width > (1u << 30) || height > (1u << 30)) {
      throw InputError(fmt::format("{}: camera {} has implausible size {}x{}", in.Where(),
                                   camera.camera_id, width, height));
    }
    camera.width = static_cast<int>(width);
    camera.height = static_cast<int>(height);
    camera.params.resize(CameraModelNumParams(camera.model_id));
    for (double& p : camera.params) p = in.Read<double>("camera parameters");
    builder->AddCamera(camera, in.Where());
  }
  in.ExpectEnd();
}

void ReadImagesBinary(const fs::path& dir, ModelBuilder* builder) {
  BinaryReader in(dir, "images.bin");
  const uint64_t num_images = in.ReadCount("images", 73);
  for (uint64_t i = 0; i < num_images; ++i) {
    Image image;
    image.image_id = in.Read<uint32_t>("image id");
    double q[4], t[3];
    for (double& v : q) v = in.Read<double>("image rotation");
    for (double& v : t) v = in.Read<double>("image translation");
    const Eigen::Quaterniond rotation(q[0], q[1], q[2], q[3]);
    if (!(std::abs(rotation.norm() - 1.0) < 1e-3)) {
      throw InputError(fmt::format("{}: image {} has a quaternion of norm {}, expected 1",
                                   in.Where(), image.image_id, rotation.norm()));
    }
    image.cam_from_world = Rigid3d(rotation.normalized(), Eigen::Vector3d(t[0], t[1], t[2]));
    image.camera_id = in.Read<uint32_t>("image camera id");
    image.name = in.ReadString("image name");
    const uint64_t num_points2D = in.ReadCount("2D points", 24);
    image.points2D.resize(num_points2D);
    for (Point2D& p : image.points2D) {
      p.xy.x() = in.Read<double>("2D point x");
      p.xy.y() = in.Read<double>("2D point y");
      in.Read<uint64_t>("2D point's 3D point id");
    }
    builder->AddImage(std::move(image), in.Where());
  }
  in.ExpectEnd();
}

void ReadPoints3DBinary(const fs::path& dir, ModelBuilder* builder) {
  BinaryReader in(dir, "points3D.bin");
  const uint64_t num_points = in.ReadCount("3D points", 51);
  for (uint64_t i = 0; i < num_points; ++i) {
    const point3D_t file_id = in.Read<uint64_t>("3D point id");
    Point3D point;
    for (int k = 0; k < 3; ++k) point.xyz(k) = in.Read<double>("3D point position");
    for (int k = 0; k < 3; ++k) point.color(k) = in.Read<uint8_t>("3D point colour");
    point.error = in.Read<double>("3D point error");
    const uint64_t track_length = in.ReadCount("track elements", 8);
    point.track.elements.resize(track_length);
    for (TrackElement& el : point.track.elements) {
      el.image_id = in.Read<uint32_t>("track image id");
      el.point2D_idx = in.Read<uint32_t>("track point index");
    }
    builder->AddPoint3D(file_id, std::move(point), in.Where());
  }
  in.ExpectEnd();
}

}  // namespace

void WriteColmapModelBinary(const fs::path& dir, const Reconstruction& reconstruction) {
  BinaryWriter cameras(dir, "cameras.bin");
  cameras.Write<uint64_t>(reconstruction.Cameras().size());
  for (camera_t id : SortedCameraIds(reconstruction)) {
    const Camera& camera = reconstruction.GetCamera(id);
    cameras.Write<uint32_t>(camera.camera_id);
    cameras.Write<int32_t>(static_cast<int32_t>(camera.model_id));
    cameras.Write<uint64_t>(camera.width);
    cameras.Write<uint64_t>(camera.height);
    for (double p : camera.params) cameras.Write<double>(p);
  }
  cameras.Finish();

  BinaryWriter images(dir, "images.bin");
  images.Write<uint64_t>(reconstruction.NumRegImages());
  for (const auto& [id, image] : reconstruction.Images()) {
    if (!image.registered) continue;
    const Eigen::Quaterniond& q = image.cam_from_world.rotation;
    const Eigen::Vector3d& t = image.cam_from_world.translation;
    images.Write<uint32_t>(image.image_id);
    for (double v : {q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()}) images.Write<double>(v);
    images.Write<uint32_t>(image.camera_id);
    images.WriteString(image.name);
    images.Write<uint64_t>(image.points2D.size());
    for (const Point2D& p : image.points2D) {
      images.Write<double>(p.xy.x());
      images.Write<double>(p.xy.y());
      images.Write<uint64_t>(WrittenPoint3DId(reconstruction, p));
    }
  }
  images.Finish();

  BinaryWriter points(dir, "points3D.bin");
  points.Write<uint64_t>(reconstruction.NumPoints3D());
  for (point3D_t id : SortedPoint3DIds(reconstruction)) {
    const Point3D& point = reconstruction.GetPoint3D(id);
    points.Write<uint64_t>(id);
    for (int k = 0; k < 3; ++k) points.Write<double>(point.xyz(k));
    for (int k = 0; k < 3; ++k) points.Write<uint8_t>(point.color(k));
    points.Write<double>(point.error);
    const std::vector<TrackElement> elements = WrittenElements(reconstruction, point);
    points.Write<uint64_t>(elements.size());
    for (const TrackElement& el : elements) {
      points.Write<uint32_t>(el.image_id);
      points.Write<uint32_t>(el.point2D_idx);
    }
  }
  points.Finish();
}

Reconstruction ReadColmapModelBinary(const fs::path& dir) {
  ModelBuilder builder;
  ReadCamerasBinary(dir, &builder);
  ReadImagesBinary(dir, &builder);
  ReadPoints3DBinary(dir, &builder);
  return builder.Finish();
}

Reconstruction ReadColmapModel(const fs::path& dir) {
  if (!fs::is_directory(dir)) {
    throw InputError(fmt::format("model folder '{}' does not exist", dir.string()));
  }
  if (fs::exists(dir / "cameras.bin")) return ReadColmapModelBinary(dir);
  if (fs::exists(dir / "cameras.txt")) return ReadColmapModelText(dir);
  throw InputError(
      fmt::format("'{}' holds neither cameras.bin nor cameras.txt; point to a COLMAP "
                  "model folder (e.g. sparse/0)",
                  dir.string()));
}

}  // namespace loopsfm
