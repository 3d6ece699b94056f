#include "loopsfm/report/report_data.h"

#include <gtest/gtest.h>

#include <map>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Two models: frames 1 and 3 registered in model 0, frame 4 in model 1, frame 2 in none.
std::vector<Reconstruction> TwoModels() {
  const Camera camera{.camera_id = 1, .model_id = CameraModelId::kPinhole, .width = 640,
                      .height = 480, .params = {500, 510, 320, 240}};
  std::vector<Reconstruction> models(2);
  for (Reconstruction& model : models) model.AddCamera(camera);
  auto add = [&](Reconstruction& model, image_t id, const Eigen::Vector3d& centre) {
    Image image;
    image.image_id = id;
    image.camera_id = 1;
    image.name = "frame_" + std::to_string(id) + ".png";
    image.points2D.resize(10);
    // Turned 90 degrees about y: world_from_cam maps the camera's z axis to world x.
    const Eigen::Quaterniond world_from_cam(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
    image.cam_from_world.rotation = world_from_cam.inverse();
    image.cam_from_world.translation = -(world_from_cam.inverse() * centre);
    model.AddImage(image);
    model.RegisterImage(id);
  };
  add(models[0], 1, {0, 0, 0});
  add(models[0], 3, {1, 2, 3});
  add(models[1], 4, {5, 5, 5});
  for (point3D_t k = 0; k < 10; ++k) {
    models[0].AddPoint3D(Eigen::Vector3d(k, 0, 1), Track(), Eigen::Matrix<uint8_t, 3, 1>(k, 20, 30));
  }
  return models;
}

TEST(ReportDataTest, FramesInTheOrderGivenWithTheirModelAndPose) {
  const std::vector<Frame> frames = {{1, 1, "frame_1.png"}, {2, 1, "frame_2.png"},
                                     {3, 1, "frame_3.png"}, {4, 1, "frame_4.png"}};
  const nlohmann::json json = ReportFrames(frames, TwoModels());
  ASSERT_EQ(json.size(), 4u);
  EXPECT_EQ(json[1]["index"], 1);
  EXPECT_EQ(json[1]["name"], "frame_2.png");
  EXPECT_FALSE(json[1]["registered"].get<bool>());
  EXPECT_FALSE(json[1].contains("center"));
  EXPECT_TRUE(json[2]["registered"].get<bool>());
  EXPECT_EQ(json[2]["model"], 0);
  EXPECT_EQ(json[3]["model"], 1);
  EXPECT_EQ(json[2]["num_points2D"], 10);
  const auto centre = json[2]["center"].get<std::vector<double>>();
  EXPECT_NEAR(centre[0], 1, 1e-12);
  EXPECT_NEAR(centre[1], 2, 1e-12);
  EXPECT_NEAR(centre[2], 3, 1e-12);
  // Row-major world_from_cam: its third column (r02, r12, r22) is the viewing direction, +x.
  const auto r = json[2]["world_from_cam_rotation"].get<std::vector<double>>();
  ASSERT_EQ(r.size(), 9u);
  EXPECT_NEAR(r[2], 1, 1e-12);
  EXPECT_NEAR(r[5], 0, 1e-12);
  EXPECT_NEAR(r[8], 0, 1e-12);
}

TEST(ReportDataTest, CamerasWithFocalAndPrincipalPoint) {
  const nlohmann::json json = ReportCameras(TwoModels()[0]);
  ASSERT_EQ(json.size(), 1u);
  EXPECT_EQ(json[0]["model"], "PINHOLE");
  EXPECT_NEAR(json[0]["focal_px"].get<double>(), 505, 1e-9);
  EXPECT_NEAR(json[0]["cx"].get<double>(), 320, 1e-9);
  EXPECT_NEAR(json[0]["cy"].get<double>(), 240, 1e-9);
}

TEST(ReportDataTest, PointsSubsampledEvenlyWithColours) {
  const Reconstruction model = TwoModels()[0];
  const nlohmann::json all = ReportPoints(model);
  EXPECT_EQ(all["xyz"].size(), 30u);
  EXPECT_EQ(all["rgb"].size(), 30u);
  const nlohmann::json some = ReportPoints(model, 4);
  ASSERT_EQ(some["xyz"].size(), 3u * 4);  // every 3rd of 10: ids 1, 4, 7, 10
  EXPECT_EQ(some["xyz"][3], 3.0);
  EXPECT_EQ(some["rgb"][3], 3);
  EXPECT_EQ(some["rgb"][4], 20);
}

TEST(ReportDataTest, TopViewPathInThePlaneOfTheCentres) {
  // A tilted ellipse: its plane's first axis is the long one.
  std::vector<Eigen::Vector3d> centres;
  for (int i = 0; i < 36; ++i) {
    const double a = 2 * M_PI * i / 36;
    centres.emplace_back(4 * std::cos(a), std::sin(a), std::sin(a) + 7);
  }
  const TopViewPlane plane = FitTopViewPlane(centres);
  const nlohmann::json path = ReportTopViewPath("loopsfm", centres, plane);
  EXPECT_EQ(path["label"], "loopsfm");
  ASSERT_EQ(path["xy"].size(), 36u);
  for (int i = 0; i < 36; ++i) {
    const double a = 2 * M_PI * i / 36;
    EXPECT_NEAR(std::abs(path["xy"][i][0].get<double>()), std::abs(4 * std::cos(a)), 1e-9);
    EXPECT_NEAR(std::abs(path["xy"][i][1].get<double>()), std::abs(std::sqrt(2.0) * std::sin(a)), 1e-9);
  }
}

TEST(ReportDataTest, TopViewLinksJoinTheDrawnCentresPerMethod) {
  std::map<std::string, Eigen::Vector3d> centres = {{"a.png", {0, 0, 0}},
                                                    {"b.png", {10, 0, 0}},
                                                    {"c.png", {10, 4, 0}},
                                                    {"d.png", {0, 4, 0}}};
  std::vector<Eigen::Vector3d> all;
  for (const auto& [name, c] : centres) all.push_back(c);
  const TopViewPlane plane = FitTopViewPlane(all);
  const nlohmann::json links = ReportTopViewLinks({{"posegraph", "a.png", "c.png", 40},
                                                   {"split", "b.png", "d.png", 3},
                                                   {"posegraph", "a.png", "d.png", 9},
                                                   {"split", "a.png", "not_drawn.png", 5}},
                                                  centres, plane);
  ASSERT_EQ(links.size(), 2u);
  EXPECT_EQ(links[0]["method"], "posegraph");
  EXPECT_EQ(links[0]["label"], "loop links (posegraph): 2");
  EXPECT_EQ(links[1]["label"], "loop links (split): 1");
  // Each segment joins the two frames' projections; lengths are those of the 3D centres.
  const nlohmann::json& ac = links[0]["segments"][0];
  const Eigen::Vector2d a = plane.Project(centres["a.png"]);
  EXPECT_NEAR(ac[0].get<double>(), a.x(), 1e-12);
  EXPECT_NEAR(ac[1].get<double>(), a.y(), 1e-12);
  EXPECT_NEAR(std::hypot(ac[2].get<double>() - ac[0].get<double>(),
                         ac[3].get<double>() - ac[1].get<double>()),
              std::hypot(10.0, 4.0), 1e-9);
  EXPECT_TRUE(ReportTopViewLinks({}, centres, plane).empty());
}

TEST(ReportDataTest, Base64OfRfc4648Vectors) {
  EXPECT_EQ(Base64Encode(""), "");
  EXPECT_EQ(Base64Encode("f"), "Zg==");
  EXPECT_EQ(Base64Encode("fo"), "Zm8=");
  EXPECT_EQ(Base64Encode("foo"), "Zm9v");
  EXPECT_EQ(Base64Encode("foob"), "Zm9vYg==");
  EXPECT_EQ(Base64Encode("fooba"), "Zm9vYmE=");
  EXPECT_EQ(Base64Encode("foobar"), "Zm9vYmFy");
  EXPECT_EQ(Base64Encode(std::string("\xff\x00\xfe", 3)), "/wD+");
}

TEST(ReportDataTest, ImageAsBase64OrAnErrorNamingTheFile) {
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("loopsfm_report_data_test_" + std::to_string(getpid()) + ".png");
  std::ofstream(file, std::ios::binary) << "foobar";
  const nlohmann::json image = ReportImage("Verified matches", file);
  EXPECT_EQ(image["title"], "Verified matches");
  EXPECT_EQ(image["png_base64"], "Zm9vYmFy");
  std::filesystem::remove(file);
  try {
    ReportImage("t", file);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos);
  }
}

}  // namespace
}  // namespace loopsfm
