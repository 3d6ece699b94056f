#include "loopsfm/scene/dataset_files.h"

#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

std::filesystem::path TempFile(const std::string& name, const std::string& text) {
  const auto path = std::filesystem::temp_directory_path() / ("loopsfm_scene_test_" + name);
  std::ofstream(path) << text;
  return path;
}

TEST(DatasetFiles, ReadsSharedDataIntrinsics) {
  const auto path = TempFile("opencv.txt",
                             "# OPENCV width height fx fy cx cy k1 k2 p1 p2\n"
                             "OPENCV 1080 1920 1375.52 1374.49 554.558 965.268 0.0578 -0.0805 "
                             "-0.00098 0.000155\n");
  const Camera camera = ReadIntrinsicsFile(path);
  EXPECT_EQ(camera.model_id, CameraModelId::kOpenCV);
  EXPECT_EQ(camera.width, 1080);
  EXPECT_EQ(camera.height, 1920);
  ASSERT_EQ(camera.params.size(), 8u);
  EXPECT_DOUBLE_EQ(camera.params[1], 1374.49);
  EXPECT_TRUE(camera.has_prior_focal_length);
}

TEST(DatasetFiles, ReadsEveryCameraModelInColmapsParameterOrder) {
  for (const CameraModelId id : kCameraModelIds) {
    SCOPED_TRACE(std::string(CameraModelName(id)));
    std::vector<double> params = {500, 510, 320, 240};
    if (CameraModelParamNames(id)[0] == "f") params = {500, 320, 240};
    while (static_cast<int>(params.size()) < CameraModelNumParams(id)) {
      params.push_back(0.01 * static_cast<double>(params.size()));
    }
    std::string line = fmt::format("{} 640 480", CameraModelName(id));
    for (const double p : params) line += fmt::format(" {}", p);
    const Camera camera = ReadIntrinsicsFile(TempFile("model.txt", "# comment\n" + line + "\n"));
    EXPECT_EQ(camera.model_id, id);
    EXPECT_EQ(camera.width, 640);
    EXPECT_EQ(camera.height, 480);
    EXPECT_EQ(camera.params, params);
  }
}

TEST(DatasetFiles, IntrinsicsRoundTripExactly) {
  for (const CameraModelId id : {CameraModelId::kOpenCVFisheye, CameraModelId::kFullOpenCV,
                                 CameraModelId::kSimpleRadial}) {
    Camera camera;
    camera.model_id = id;
    camera.width = 960;
    camera.height = 540;
    camera.params = {1.0 / 3.0 * 1000, 0.1 + 0.2, 479.5, 270.25};
    while (static_cast<int>(camera.params.size()) < CameraModelNumParams(id)) {
      camera.params.push_back(-1e-7 / (camera.params.size() + 1.0));
    }
    camera.params.resize(CameraModelNumParams(id));
    const auto path = std::filesystem::temp_directory_path() / "loopsfm_scene_test_write.txt";
    WriteIntrinsicsFile(path, camera);
    const Camera read = ReadIntrinsicsFile(path);
    EXPECT_EQ(read.model_id, id);
    EXPECT_EQ(read.width, 960);
    EXPECT_EQ(read.height, 540);
    EXPECT_EQ(read.params, camera.params);  // bit for bit
  }
}

// Bad lines name the file and line, what was expected and the line of every model.
TEST(DatasetFiles, RejectsBadCameraLinesWithLineNumberAndTheModels) {
  auto expect_error = [](const std::string& name, const std::string& text,
                         const std::vector<std::string>& words) {
    try {
      ReadIntrinsicsFile(TempFile(name, text));
      ADD_FAILURE() << "accepted '" << text << "'";
    } catch (const InputError& e) {
      const std::string message = e.what();
      for (const std::string& word : words) {
        EXPECT_NE(message.find(word), std::string::npos) << "'" << word << "' in " << message;
      }
    }
  };
  const std::string models =
      "'SIMPLE_PINHOLE width height f cx cy', 'PINHOLE width height fx fy cx cy', "
      "'SIMPLE_RADIAL width height f cx cy k', 'RADIAL width height f cx cy k1 k2', "
      "'OPENCV width height fx fy cx cy k1 k2 p1 p2', "
      "'OPENCV_FISHEYE width height fx fy cx cy k1 k2 k3 k4', "
      "'FULL_OPENCV width height fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6', "
      "'SIMPLE_RADIAL_FISHEYE width height f cx cy k', "
      "'RADIAL_FISHEYE width height f cx cy k1 k2'";
  expect_error("count.txt", "# comment\nPINHOLE 640 480 500 500 320\n",
               {"count.txt:2: camera model PINHOLE takes 4 parameters after the image size "
                "(fx, fy, cx, cy), got 3: 'PINHOLE 640 480 500 500 320'",
                models});
  expect_error("fisheye.txt", "OPENCV_FISHEYE 640 480 500 500 320 240 0.1 0.01 0.001\n",
               {"fisheye.txt:1: camera model OPENCV_FISHEYE takes 8 parameters", "got 7", models});
  expect_error("model.txt", "\n\nKANNALA 1 1 1 1 1 1\n",
               {"model.txt:3: unknown camera model 'KANNALA'", models});
  expect_error("size.txt", "RADIAL wide 480 500 320 240 0.1 0.01\n",
               {"size.txt:1: expected the image width and height after RADIAL", models});
  expect_error("number.txt", "RADIAL 640 480 500 320 240 0.1 x\n",
               {"number.txt:1: expected numbers after the image size", models});
  expect_error("focal.txt", "SIMPLE_RADIAL_FISHEYE 640 480 -500 320 240 0.1\n",
               {"focal.txt:1: camera focal length must be positive"});
  expect_error("empty.txt", "# nothing\n", {"holds no camera line", models});
  EXPECT_THROW(ReadIntrinsicsFile("/nonexistent/intrinsics.txt"), InputError);
}

TEST(DatasetFiles, TrajectoryRoundTrips) {
  std::vector<TrajectoryEntry> entries(2);
  entries[0].name = "frame_000000.png";
  entries[1].name = "frame_000001.png";
  entries[1].world_from_cam = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(1.5, -2, 0.25));
  const auto path = std::filesystem::temp_directory_path() / "loopsfm_scene_test_traj.txt";
  WriteTrajectoryFile(path, entries);
  const auto read = ReadTrajectoryFile(path);
  ASSERT_EQ(read.size(), 2u);
  EXPECT_EQ(read[1].name, "frame_000001.png");
  EXPECT_LT((read[1].world_from_cam.translation - entries[1].world_from_cam.translation).norm(),
            1e-8);
  EXPECT_LT(read[1].world_from_cam.rotation.angularDistance(entries[1].world_from_cam.rotation),
            1e-8);
}

TEST(DatasetFiles, LoopLinksRoundTripAndBadLinesAreNamed) {
  const std::vector<LoopLink> links = {{"posegraph", "frame_000012.png", "frame_000251.png", 407},
                                       {"split", "frame_000030.png", "frame_000270.png", 3}};
  const auto path = std::filesystem::temp_directory_path() / "loopsfm_scene_test_links.txt";
  WriteLoopLinksFile(path, links);
  const std::vector<LoopLink> read = ReadLoopLinksFile(path);
  ASSERT_EQ(read.size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(read[k].method, links[k].method);
    EXPECT_EQ(read[k].old_frame, links[k].old_frame);
    EXPECT_EQ(read[k].recent_frame, links[k].recent_frame);
    EXPECT_EQ(read[k].num_point_pairs, links[k].num_point_pairs);
  }
  WriteLoopLinksFile(path, {});
  EXPECT_TRUE(ReadLoopLinksFile(path).empty());

  for (const std::string bad : {"posegraph a.png b.png", "posegraph a.png b.png 3 extra",
                                "bundle a.png b.png 3", "split a.png b.png -1"}) {
    try {
      ReadLoopLinksFile(TempFile("bad_links.txt", "# header\n" + bad + "\n"));
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const InputError& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find("bad_links.txt:2"), std::string::npos) << message;
      EXPECT_NE(message.find("method old_frame recent_frame point_pairs"), std::string::npos)
          << message;
    }
  }
}

}  // namespace
}  // namespace loopsfm
