#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <fstream>
#include <sstream>

#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/storage/model_io_test_scene.h"
#include "loopsfm/storage/ply.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;
using model_io_test::ExpectSameModel;
using model_io_test::MakeScene;

class ModelIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ =
        fs::temp_directory_path() / fmt::format("loopsfm_model_io_{}_{}", getpid(), info->name());
    fs::remove_all(dir_);
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }
  std::string ReadFile(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }
  void WriteFile(const fs::path& path, const std::string& data) {
    std::ofstream(path, std::ios::binary) << data;
  }
  // Runs f and returns the InputError's message ("" when nothing was thrown).
  template <typename F>
  std::string InputErrorOf(F&& f) {
    try {
      f();
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  }
  fs::path dir_;
};

TEST_F(ModelIoTest, BinaryRoundTripIsExact) {
  const Reconstruction rec = MakeScene();
  WriteColmapModelBinary(dir_, rec);
  const Reconstruction read = ReadColmapModelBinary(dir_);
  ExpectSameModel(rec, read, 0.0);
  EXPECT_EQ(read.NumImages(), 5u);  // the unregistered image is not written
  EXPECT_EQ(read.NumPoints3D(), 39u);
  // Ids 1..4 are kept; the gap at 5 closes.
  EXPECT_TRUE(read.ExistsPoint3D(4));
  EXPECT_FALSE(read.ExistsPoint3D(40));
  EXPECT_DOUBLE_EQ(read.GetPoint3D(3).error, rec.GetPoint3D(3).error);
  EXPECT_EQ(ReadColmapModel(dir_).NumPoints3D(), 39u);
}

TEST_F(ModelIoTest, TextRoundTripIsExact) {
  const Reconstruction rec = MakeScene();
  WriteColmapModelText(dir_, rec);
  const Reconstruction read = ReadColmapModelText(dir_);
  ExpectSameModel(rec, read, 0.0);
  EXPECT_EQ(ReadColmapModel(dir_).NumRegImages(), 5u);
  // Text and binary readers agree.
  WriteColmapModelBinary(dir_ / "bin", read);
  ExpectSameModel(rec, ReadColmapModelBinary(dir_ / "bin"), 0.0);
}

TEST_F(ModelIoTest, BinaryLayoutHasColmapSizesAndFields) {
  const Reconstruction rec = MakeScene();
  WriteColmapModelBinary(dir_, rec);
  // cameras: count, then per camera 4 + 4 + 8 + 8 bytes and the parameters.
  const std::string cameras = ReadFile(dir_ / "cameras.bin");
  EXPECT_EQ(cameras.size(), 8u + (24 + 4 * 8) + (24 + 8 * 8));
  uint64_t count;
  uint32_t camera_id;
  int32_t model_id;
  uint64_t width;
  std::memcpy(&count, cameras.data(), 8);
  std::memcpy(&camera_id, cameras.data() + 8, 4);
  std::memcpy(&model_id, cameras.data() + 12, 4);
  std::memcpy(&width, cameras.data() + 16, 8);
  EXPECT_EQ(count, 2u);
  EXPECT_EQ(camera_id, 1u);
  EXPECT_EQ(model_id, 1);  // PINHOLE
  EXPECT_EQ(width, 640u);

  // images: per image 4 + 7 * 8 + 4 + name + '\0' + 8 + 24 per 2D point.
  size_t expected_images = 8;
  for (image_t id : rec.RegImageIds()) {
    const Image& image = rec.GetImage(id);
    expected_images += 4 + 56 + 4 + image.name.size() + 1 + 8 + 24 * image.points2D.size();
  }
  const std::string images = ReadFile(dir_ / "images.bin");
  EXPECT_EQ(images.size(), expected_images);
  double qw;
  std::memcpy(&qw, images.data() + 12, 8);
  EXPECT_DOUBLE_EQ(qw, rec.GetImage(1).cam_from_world.rotation.w());
  EXPECT_EQ(images.substr(8 + 64, rec.GetImage(1).name.size() + 1),
            rec.GetImage(1).name + std::string(1, '\0'));
  // The second-last 2D point of image 1 observes nothing: id 2^64 - 1.
  const size_t points_start = 8 + 64 + rec.GetImage(1).name.size() + 1 + 8;
  const size_t last = rec.GetImage(1).points2D.size() - 1;
  uint64_t no_point;
  std::memcpy(&no_point, images.data() + points_start + 24 * last + 16, 8);
  EXPECT_EQ(no_point, ~uint64_t{0});

  // points3D: per point 8 + 24 + 3 + 8 + 8 + 8 per registered track element.
  size_t expected_points = 8;
  for (const auto& [id, point] : rec.Points3D()) {
    size_t registered = 0;
    for (const auto& el : point.track.elements) registered += rec.IsRegistered(el.image_id);
    expected_points += 51 + 8 * registered;
  }
  EXPECT_EQ(ReadFile(dir_ / "points3D.bin").size(), expected_points);
}

TEST_F(ModelIoTest, TextFilesHaveColmapLines) {
  WriteColmapModelText(dir_, MakeScene());
  const std::string cameras = ReadFile(dir_ / "cameras.txt");
  EXPECT_NE(cameras.find("\n1 PINHOLE 640 480 501.25 499.5 320.1 239.7\n"), std::string::npos)
      << cameras;
  EXPECT_NE(cameras.find("# Number of cameras: 2\n"), std::string::npos);
  const std::string images = ReadFile(dir_ / "images.txt");
  EXPECT_NE(images.find(" 1 frame_1001.png\n"), std::string::npos);
  EXPECT_NE(images.find(" 10.5 20.25 -1 "), std::string::npos);
  EXPECT_EQ(images.find("frame_1006"), std::string::npos);
  const std::string points = ReadFile(dir_ / "points3D.txt");
  EXPECT_NE(points.find("\n1 "), std::string::npos);
  EXPECT_EQ(points.find("\n5 "), std::string::npos);
}

// Cameras of every model keep COLMAP's model id (binary) and name (text) and their parameters;
// COLMAP's FOV model (id 7) is refused with the list of supported models.
TEST_F(ModelIoTest, EveryCameraModelRoundTripsWithColmapsIdsAndNames) {
  Reconstruction rec;
  for (const CameraModelId id : kCameraModelIds) {
    Camera camera;
    camera.camera_id = 10 + static_cast<camera_t>(id);
    camera.model_id = id;
    camera.width = 1920;
    camera.height = 1080;
    for (int i = 0; i < CameraModelNumParams(id); ++i) camera.params.push_back(1000.0 / (i + 3));
    rec.AddCamera(camera);
  }
  WriteColmapModelBinary(dir_ / "bin", rec);
  WriteColmapModelText(dir_ / "txt", rec);
  for (const Reconstruction& read :
       {ReadColmapModelBinary(dir_ / "bin"), ReadColmapModelText(dir_ / "txt")}) {
    ASSERT_EQ(read.Cameras().size(), kCameraModelIds.size());
    for (const CameraModelId id : kCameraModelIds) {
      const Camera& camera = read.GetCamera(10 + static_cast<camera_t>(id));
      EXPECT_EQ(camera.model_id, id);
      EXPECT_TRUE(camera.SameIntrinsics(rec.GetCamera(camera.camera_id))) << camera.ModelName();
    }
  }
  // cameras.bin: count, then per camera id (uint32), model id (int32), width, height, params.
  const std::string cameras = ReadFile(dir_ / "bin" / "cameras.bin");
  size_t offset = 8;
  for (const CameraModelId id : kCameraModelIds) {
    int32_t model_id;
    std::memcpy(&model_id, cameras.data() + offset + 4, 4);
    EXPECT_EQ(model_id, static_cast<int>(id));
    offset += 4 + 4 + 8 + 8 + 8 * CameraModelNumParams(id);
  }
  EXPECT_NE(ReadFile(dir_ / "txt" / "cameras.txt")
                .find("16 FULL_OPENCV 1920 1080 333.3333333333333 250 200"),
            std::string::npos);
  std::string fov = cameras;
  const int32_t fov_id = 7;
  std::memcpy(fov.data() + 8 + 4, &fov_id, 4);
  WriteFile(dir_ / "bin" / "cameras.bin", fov);
  const std::string message = InputErrorOf([&] { ReadColmapModelBinary(dir_ / "bin"); });
  EXPECT_NE(message.find("COLMAP camera model id 7, which loopsfm does not support (supported: "
                         "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, "
                         "FULL_OPENCV, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE)"),
            std::string::npos)
      << message;
}

TEST_F(ModelIoTest, MissingAndCorruptFilesThrowInputError) {
  EXPECT_NE(InputErrorOf([&] { ReadColmapModel(dir_ / "nothing"); }).find("does not exist"),
            std::string::npos);
  EXPECT_NE(InputErrorOf([&] { ReadColmapModelBinary(dir_); }).find("cameras.bin"),
            std::string::npos);
  fs::create_directories(dir_);
  EXPECT_NE(InputErrorOf([&] { ReadColmapModel(dir_); }).find("neither"), std::string::npos);

  const Reconstruction rec = MakeScene();
  WriteColmapModelBinary(dir_, rec);
  const std::string cameras = ReadFile(dir_ / "cameras.bin");
  const std::string images = ReadFile(dir_ / "images.bin");
  // Truncated inside the last camera's parameters.
  WriteFile(dir_ / "cameras.bin", cameras.substr(0, cameras.size() - 10));
  std::string message = InputErrorOf([&] { ReadColmapModelBinary(dir_); });
  EXPECT_NE(message.find("cameras.bin' ends early while reading camera parameters"),
            std::string::npos)
      << message;
  WriteFile(dir_ / "cameras.bin", cameras);
  // Truncated inside the last image's 2D points: the count no longer fits.
  WriteFile(dir_ / "images.bin", images.substr(0, images.size() - 10));
  message = InputErrorOf([&] { ReadColmapModelBinary(dir_); });
  EXPECT_NE(message.find("claims 42 2D points"), std::string::npos) << message;
  // An absurd image count.
  std::string corrupt = images;
  corrupt[6] = '\x7f';
  WriteFile(dir_ / "images.bin", corrupt);
  EXPECT_NE(InputErrorOf([&] { ReadColmapModelBinary(dir_); }).find("claims"), std::string::npos);
  // Trailing garbage.
  WriteFile(dir_ / "images.bin", images + "xyz");
  EXPECT_NE(InputErrorOf([&] { ReadColmapModelBinary(dir_); }).find("3 unexpected bytes"),
            std::string::npos);
  // Missing points file.
  WriteFile(dir_ / "images.bin", images);
  fs::remove(dir_ / "points3D.bin");
  EXPECT_NE(InputErrorOf([&] { ReadColmapModelBinary(dir_); }).find("points3D.bin"),
            std::string::npos);
}

TEST_F(ModelIoTest, InconsistentTextModelsNameFileAndLine) {
  WriteColmapModelText(dir_, MakeScene());
  const std::string cameras = ReadFile(dir_ / "cameras.txt");
  const std::string points = ReadFile(dir_ / "points3D.txt");

  WriteFile(dir_ / "cameras.txt", "# c\n1 FISHEYE_X 640 480 1 2 3\n");
  std::string message = InputErrorOf([&] { ReadColmapModelText(dir_); });
  EXPECT_NE(message.find("cameras.txt':2: camera model 'FISHEYE_X'"), std::string::npos) << message;
  WriteFile(dir_ / "cameras.txt", "1 PINHOLE 640 480 500 500 320\n");
  message = InputErrorOf([&] { ReadColmapModelText(dir_); });
  EXPECT_NE(message.find("takes 4 parameters"), std::string::npos) << message;
  WriteFile(dir_ / "cameras.txt", "1 PINHOLE 640 480 500 500 320 240\n");  // camera 7 missing
  message = InputErrorOf([&] { ReadColmapModelText(dir_); });
  EXPECT_NE(message.find("uses camera 7"), std::string::npos) << message;

  WriteFile(dir_ / "cameras.txt", cameras);
  WriteFile(dir_ / "points3D.txt", "1 0 0 5 1 2 3 0.5 1 0 99 0\n");
  message = InputErrorOf([&] { ReadColmapModelText(dir_); });
  EXPECT_NE(message.find("points3D.txt':1: 3D point 1 is observed by image 99"), std::string::npos)
      << message;
  WriteFile(dir_ / "points3D.txt", "1 0 0 5 1 2 3 0.5 1 0 2 100000\n");
  message = InputErrorOf([&] { ReadColmapModelText(dir_); });
  EXPECT_NE(message.find("which has only"), std::string::npos) << message;
  WriteFile(dir_ / "points3D.txt", "1 0 0 5 1 2 3 0.5 1 0 2 0\n2 0 0 5 1 2 3 0.5 1 0 3 0\n");
  message = InputErrorOf([&] { ReadColmapModelText(dir_); });
  EXPECT_NE(message.find("more than one 3D point"), std::string::npos) << message;
  WriteFile(dir_ / "points3D.txt", "1 0 0 5 1 2 300 0.5 1 0 2 0\n");
  message = InputErrorOf([&] { ReadColmapModelText(dir_); });
  EXPECT_NE(message.find(":1: expected colours in 0..255"), std::string::npos) << message;
  WriteFile(dir_ / "points3D.txt", points);
  EXPECT_EQ(ReadColmapModelText(dir_).NumPoints3D(), 39u);
}

TEST_F(ModelIoTest, TextWriterRefusesNamesWithSpaces) {
  Reconstruction rec = MakeScene();
  Image image = rec.GetImage(6);
  image.image_id = 8;
  image.name = "my frame.png";
  for (auto& p : image.points2D) p.point3D_id = kInvalidPoint3DId;
  rec.AddImage(image);
  rec.RegisterImage(8);
  EXPECT_THROW(WriteColmapModelText(dir_, rec), StorageError);
  WriteColmapModelBinary(dir_, rec);
  EXPECT_EQ(ReadColmapModelBinary(dir_).GetImage(8).name, "my frame.png");
}

TEST_F(ModelIoTest, PlyHasStandardHeaderAndOneVertexPerPoint) {
  const Reconstruction rec = MakeScene();
  for (const bool double_precision : {false, true}) {
    PlyOptions options;
    options.double_precision = double_precision;
    const fs::path path = dir_ / (double_precision ? "d.ply" : "f.ply");
    WritePly(path, rec, options);
    const std::string data = ReadFile(path);
    const std::string type = double_precision ? "double" : "float";
    const std::string header =
        "ply\nformat binary_little_endian 1.0\ncomment written by loopsfm\n"
        "element vertex 39\nproperty " +
        type + " x\nproperty " + type + " y\nproperty " + type +
        " z\nproperty uchar red\n"
        "property uchar green\nproperty uchar blue\nend_header\n";
    ASSERT_EQ(data.substr(0, header.size()), header);
    const size_t record = double_precision ? 27 : 15;
    ASSERT_EQ(data.size(), header.size() + 39 * record);
    // First vertex is point 1.
    const Point3D& first = rec.GetPoint3D(1);
    const char* v = data.data() + header.size();
    if (double_precision) {
      double x;
      std::memcpy(&x, v, 8);
      EXPECT_EQ(x, first.xyz.x());
    } else {
      float z;
      std::memcpy(&z, v + 8, 4);
      EXPECT_EQ(z, static_cast<float>(first.xyz.z()));
    }
    EXPECT_EQ(static_cast<uint8_t>(v[record - 3]), first.color(0));
    EXPECT_EQ(static_cast<uint8_t>(v[record - 1]), first.color(2));
  }
  EXPECT_THROW(WritePly("/proc/loopsfm_cannot_write/x.ply", rec), StorageError);
}

}  // namespace
}  // namespace loopsfm
