#include "loopsfm/storage/colmap_model.h"

#include <fstream>
#include <sstream>

#include "loopsfm/storage/colmap_model_internal.h"
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

// Lines of a text model file with their numbers.
class TextReader {
 public:
  TextReader(const fs::path& dir, const char* name) : path_(dir / name), in_(path_) {
    if (!in_) {
      throw InputError(
          fmt::format("cannot read '{}': a COLMAP text model folder holds "
                      "cameras.txt, images.txt and points3D.txt",
                      path_.string()));
    }
  }
  std::string Where() const { return fmt::format("'{}':{}", path_.string(), line_number_); }
  // The next line that is neither blank nor a comment; false at the end of the file.
  bool NextDataLine(std::string* line) {
    while (NextLine(line)) {
      const auto first = line->find_first_not_of(" \t\r");
      if (first != std::string::npos && (*line)[first] != '#') return true;
    }
    return false;
  }
  // The next line whatever it holds; false (and an empty line) at the end of the file.
  bool NextLine(std::string* line) {
    if (!std::getline(in_, *line)) {
      line->clear();
      return false;
    }
    ++line_number_;
    return true;
  }
  [[noreturn]] void Fail(const std::string& expected, const std::string& line) const {
    throw InputError(fmt::format("{}: expected {}, got '{}'", Where(), expected, line));
  }

 private:
  fs::path path_;
  std::ifstream in_;
  int line_number_ = 0;
};

void ReadCamerasText(const fs::path& dir, ModelBuilder* builder) {
  TextReader in(dir, "cameras.txt");
  for (std::string line; in.NextDataLine(&line);) {
    std::istringstream fields(line);
    Camera camera;
    std::string model_name;
    if (!(fields >> camera.camera_id >> model_name >> camera.width >> camera.height)) {
      in.Fail("'CAMERA_ID MODEL WIDTH HEIGHT PARAMS...'", line);
    }
    const auto model = CameraModelFromName(model_name);
    if (!model) {
      throw InputError(
          fmt::format("{}: camera model '{}' is not supported by loopsfm (supported: {})",
                      in.Where(), model_name, CameraModelNameList()));
    }
    camera.model_id = *model;
    for (double p; fields >> p;) camera.params.push_back(p);
    if (!fields.eof()) in.Fail("numeric camera parameters", line);
    builder->AddCamera(camera, in.Where());
  }
}

void ReadImagesText(const fs::path& dir, ModelBuilder* builder) {
  TextReader in(dir, "images.txt");
  for (std::string line; in.NextDataLine(&line);) {
    std::istringstream fields(line);
    Image image;
    double qw, qx, qy, qz, tx, ty, tz;
    if (!(fields >> image.image_id >> qw >> qx >> qy >> qz >> tx >> ty >> tz >> image.camera_id >>
          image.name)) {
      in.Fail("'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME'", line);
    }
    const Eigen::Quaterniond rotation(qw, qx, qy, qz);
    if (!(std::abs(rotation.norm() - 1.0) < 1e-3)) {
      throw InputError(fmt::format("{}: image {} has a quaternion of norm {}, expected 1",
                                   in.Where(), image.image_id, rotation.norm()));
    }
    image.cam_from_world = Rigid3d(rotation.normalized(), Eigen::Vector3d(tx, ty, tz));
    const std::string where = in.Where();
    // The second line of an image lists its 2D points (empty when it has none).
    std::string points_line;
    in.NextLine(&points_line);
    std::istringstream points(points_line);
    Point2D p;
    std::string id;
    while (points >> p.xy.x()) {
      if (!(points >> p.xy.y() >> id)) in.Fail("'X Y POINT3D_ID' triples", points_line);
      image.points2D.push_back(p);
    }
    if (!points.eof()) in.Fail("'X Y POINT3D_ID' triples", points_line);
    builder->AddImage(std::move(image), where);
  }
}

void ReadPoints3DText(const fs::path& dir, ModelBuilder* builder) {
  TextReader in(dir, "points3D.txt");
  for (std::string line; in.NextDataLine(&line);) {
    std::istringstream fields(line);
    point3D_t file_id;
    Point3D point;
    int rgb[3];
    if (!(fields >> file_id >> point.xyz.x() >> point.xyz.y() >> point.xyz.z() >> rgb[0] >>
          rgb[1] >> rgb[2] >> point.error)) {
      in.Fail("'POINT3D_ID X Y Z R G B ERROR TRACK...'", line);
    }
    for (int k = 0; k < 3; ++k) {
      if (rgb[k] < 0 || rgb[k] > 255) in.Fail("colours in 0..255", line);
      point.color(k) = static_cast<uint8_t>(rgb[k]);
    }
    TrackElement el;
    while (fields >> el.image_id) {
      if (!(fields >> el.point2D_idx)) in.Fail("'IMAGE_ID POINT2D_IDX' pairs", line);
      point.track.elements.push_back(el);
    }
    if (!fields.eof()) in.Fail("'IMAGE_ID POINT2D_IDX' pairs", line);
    builder->AddPoint3D(file_id, std::move(point), in.Where());
  }
}

}  // namespace

void WriteColmapModelText(const fs::path& dir, const Reconstruction& reconstruction) {
  for (const auto& [id, image] : reconstruction.Images()) {
    if (image.registered &&
        (image.name.empty() || image.name.find_first_of(" \t\r\n") != std::string::npos)) {
      throw StorageError(
          fmt::format("image name '{}' is empty or holds whitespace, which "
                      "COLMAP's text format cannot store; write the binary "
                      "format instead",
                      image.name));
    }
  }

  std::ofstream cameras = OpenForWriting(dir, "cameras.txt", false);
  cameras << "# Camera list with one line of data per camera:\n"
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
          << "# Number of cameras: " << reconstruction.Cameras().size() << "\n";
  for (camera_t id : SortedCameraIds(reconstruction)) {
    const Camera& camera = reconstruction.GetCamera(id);
    cameras << fmt::format("{} {} {} {}", camera.camera_id, camera.ModelName(), camera.width,
                           camera.height);
    for (double p : camera.params) cameras << fmt::format(" {}", p);
    cameras << '\n';
  }
  FinishWriting(cameras, dir / "cameras.txt");

  std::ofstream images = OpenForWriting(dir, "images.txt", false);
  images << "# Image list with two lines of data per image:\n"
            "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
            "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
         << fmt::format("# Number of images: {}, mean observations per image: {}\n",
                        reconstruction.NumRegImages(),
                        reconstruction.ComputeMeanObservationsPerRegImage());
  for (const auto& [id, image] : reconstruction.Images()) {
    if (!image.registered) continue;
    const Eigen::Quaterniond& q = image.cam_from_world.rotation;
    const Eigen::Vector3d& t = image.cam_from_world.translation;
    images << fmt::format("{} {} {} {} {} {} {} {} {} {}\n", image.image_id, q.w(), q.x(), q.y(),
                          q.z(), t.x(), t.y(), t.z(), image.camera_id, image.name);
    std::string points_line;
    for (const Point2D& p : image.points2D) {
      const point3D_t point3D_id = WrittenPoint3DId(reconstruction, p);
      if (!points_line.empty()) points_line += ' ';
      points_line += point3D_id == kInvalidPoint3DId
                         ? fmt::format("{} {} -1", p.xy.x(), p.xy.y())
                         : fmt::format("{} {} {}", p.xy.x(), p.xy.y(), point3D_id);
    }
    images << points_line << '\n';
  }
  FinishWriting(images, dir / "images.txt");

  std::ofstream points = OpenForWriting(dir, "points3D.txt", false);
  points << "# 3D point list with one line of data per point:\n"
            "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
         << fmt::format("# Number of points: {}, mean track length: {}\n",
                        reconstruction.NumPoints3D(), reconstruction.ComputeMeanTrackLength());
  for (point3D_t id : SortedPoint3DIds(reconstruction)) {
    const Point3D& point = reconstruction.GetPoint3D(id);
    points << fmt::format("{} {} {} {} {} {} {} {}", id, point.xyz.x(), point.xyz.y(),
                          point.xyz.z(), point.color(0), point.color(1), point.color(2),
                          point.error);
    for (const TrackElement& el : WrittenElements(reconstruction, point)) {
      points << fmt::format(" {} {}", el.image_id, el.point2D_idx);
    }
    points << '\n';
  }
  FinishWriting(points, dir / "points3D.txt");
}

Reconstruction ReadColmapModelText(const fs::path& dir) {
  ModelBuilder builder;
  ReadCamerasText(dir, &builder);
  ReadImagesText(dir, &builder);
  ReadPoints3DText(dir, &builder);
  return builder.Finish();
}

}  // namespace loopsfm
