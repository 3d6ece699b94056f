#include "loopsfm/scene/dataset_files.h"

#include <gtest/gtest.h>

#include <fstream>

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

TEST(DatasetFiles, RejectsWrongParameterCountWithLineNumber) {
  const auto path = TempFile("bad.txt", "# comment\nPINHOLE 640 480 500 500 320\n");
  try {
    ReadIntrinsicsFile(path);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(":2:"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("takes 4 parameters"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadIntrinsicsFile(TempFile("model.txt", "KANNALA 1 1 1 1 1 1\n")), InputError);
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

}  // namespace
}  // namespace loopsfm
