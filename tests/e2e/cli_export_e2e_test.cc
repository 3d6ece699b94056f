// Exports as other tools read them: the frames, nerfstudio's transforms.json, the
// undistorted (Gaussian-splatting) layout read back by COLMAP itself, and `loopsfm export`
// re-exporting a finished run. One reconstruction of a rendered image folder with radial
// distortion (SIMPLE_RADIAL, k1 = -0.12) serves every test.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cli_test_util.h"
#include "loopsfm/storage/colmap_model.h"

namespace loopsfm::e2e {
namespace {

constexpr int kNumFrames = 24;

// A COLMAP text model as COLMAP's model_converter writes it, with projection written here
// (not loopsfm's camera code) for the two models the test meets.
struct TextModel {
  struct Cam {
    std::string model;
    int width = 0, height = 0;
    std::vector<double> params;
  };
  struct Obs {
    double x, y;
    long long point3D_id;
  };
  struct Img {
    Eigen::Quaterniond q;
    Eigen::Vector3d t;
    int camera_id;
    std::string name;
    std::vector<Obs> obs;
  };
  std::map<int, Cam> cameras;
  std::map<long long, Eigen::Vector3d> points;
  std::vector<Img> images;

  static TextModel Read(const fs::path& dir) {
    TextModel m;
    for (const std::string& line : DataLines(dir / "cameras.txt")) {
      std::istringstream in(line);
      int id;
      Cam cam;
      in >> id >> cam.model >> cam.width >> cam.height;
      for (double p; in >> p;) cam.params.push_back(p);
      m.cameras[id] = cam;
    }
    for (const std::string& line : DataLines(dir / "points3D.txt")) {
      std::istringstream in(line);
      long long id;
      Eigen::Vector3d xyz;
      in >> id >> xyz.x() >> xyz.y() >> xyz.z();
      m.points[id] = xyz;
    }
    // images.txt: two lines per image; the second may be empty, so read it raw.
    std::ifstream in(dir / "images.txt");
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      Img img;
      std::istringstream head(line);
      int id;
      head >> id >> img.q.w() >> img.q.x() >> img.q.y() >> img.q.z() >> img.t.x() >> img.t.y() >>
          img.t.z() >> img.camera_id >> img.name;
      std::getline(in, line);
      std::istringstream obs(line);
      for (Obs o; obs >> o.x >> o.y >> o.point3D_id;) img.obs.push_back(o);
      m.images.push_back(img);
    }
    return m;
  }

  static Eigen::Vector2d Project(const Cam& cam, const Eigen::Vector3d& p) {
    const double u = p.x() / p.z(), v = p.y() / p.z();
    const std::vector<double>& k = cam.params;
    if (cam.model == "PINHOLE") return {k[0] * u + k[2], k[1] * v + k[3]};
    EXPECT_EQ(cam.model, "SIMPLE_RADIAL");
    const double d = 1.0 + k[3] * (u * u + v * v);
    return {k[0] * u * d + k[1], k[0] * v * d + k[2]};
  }

  // Mean reprojection error over every observation of a 3D point.
  double MeanReprojectionError() const {
    double sum = 0.0;
    int n = 0;
    for (const Img& img : images) {
      for (const Obs& o : img.obs) {
        if (o.point3D_id < 0) continue;
        const Eigen::Vector3d in_cam = img.q.normalized() * points.at(o.point3D_id) + img.t;
        sum += (Project(cameras.at(img.camera_id), in_cam) - Eigen::Vector2d(o.x, o.y)).norm();
        ++n;
      }
    }
    return n > 0 ? sum / n : -1.0;
  }
};

class CliExportTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / fmt::format("loopsfm_e2e_{}_export", getpid()));
    fs::remove_all(*dir_);
    fs::create_directories(*dir_);
    const CommandResult synth =
        RunLoopsfm({"-q", "synth", "cylinder", "-o", Scene().string(), "--frames",
                    std::to_string(kNumFrames), "--camera-model", "SIMPLE_RADIAL", "--k1", "-0.12"});
    if (synth.exit_code != 0) {
      *error_ = ::testing::PrintToString(synth);
      return;
    }
    *reconstruct_ = RunLoopsfm({"-q", "reconstruct", (Scene() / "images").string(), "-o",
                                Out().string(), "--intrinsics",
                                (Scene() / "intrinsics.txt").string(), "--export", "all"});
  }
  static void TearDownTestSuite() {
    if (!::testing::UnitTest::GetInstance()->Failed()) {
      std::error_code ignored;
      fs::remove_all(*dir_, ignored);
    }
  }
  void SetUp() override {
    ASSERT_TRUE(error_->empty()) << *error_;
    ASSERT_EQ(reconstruct_->exit_code, 0) << *reconstruct_;
  }
  static fs::path Scene() { return *dir_ / "scene"; }
  static fs::path Out() { return *dir_ / "out"; }

  static inline fs::path* dir_ = nullptr;
  static inline std::string* error_ = new std::string;
  static inline CommandResult* reconstruct_ = new CommandResult;
};

TEST_F(CliExportTest, FramesAreCopiedAsTheyAreNamedInTheModel) {
  const Reconstruction model = ReadColmapModel(Out() / "sparse" / "0");
  int copied = 0;
  for (const auto& entry : fs::directory_iterator(Scene() / "images")) {
    const fs::path copy = Out() / "images" / entry.path().filename();
    ASSERT_TRUE(fs::exists(copy)) << copy;
    EXPECT_EQ(ReadFileBytes(copy), ReadFileBytes(entry.path())) << copy;
    ++copied;
  }
  EXPECT_EQ(copied, kNumFrames);
  for (const auto& [id, image] : model.Images()) {
    EXPECT_TRUE(fs::exists(Out() / "images" / image.name)) << image.name;
  }
}

TEST_F(CliExportTest, TransformsJsonConvertsBackToTheColmapModel) {
  const Reconstruction model = ReadColmapModel(Out() / "sparse" / "0");
  std::ifstream in(Out() / "transforms.json");
  const nlohmann::json transforms = nlohmann::json::parse(in);
  const Camera& camera = model.Cameras().begin()->second;
  EXPECT_EQ(transforms["camera_model"], "OPENCV");
  EXPECT_EQ(transforms["w"], camera.width);
  EXPECT_EQ(transforms["h"], camera.height);
  EXPECT_DOUBLE_EQ(transforms["fl_x"].get<double>(), camera.params[0]);
  EXPECT_DOUBLE_EQ(transforms["k1"].get<double>(), camera.params[3]);
  EXPECT_EQ(transforms["ply_file_path"], "points.ply");
  ASSERT_EQ(transforms["frames"].size(), model.NumRegImages());
  std::map<std::string, image_t> by_name;
  for (const auto& [id, image] : model.Images()) by_name[image.name] = id;
  for (const nlohmann::json& frame : transforms["frames"]) {
    const fs::path file = frame["file_path"].get<std::string>();
    ASSERT_TRUE(fs::exists(Out() / file)) << file;
    const Image& image = model.GetImage(by_name.at(file.filename().string()));
    Eigen::Matrix4d c2w;
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) c2w(r, c) = frame["transform_matrix"][r][c].get<double>();
    }
    // OpenGL (x right, y up, z back) to OpenCV (x right, y down, z forward) camera axes.
    c2w.col(1) *= -1.0;
    c2w.col(2) *= -1.0;
    const Eigen::Matrix4d cam_from_world = c2w.inverse();
    const Eigen::Matrix<double, 3, 4> expected = image.cam_from_world.ToMatrix();
    EXPECT_LT((cam_from_world.topRows<3>() - expected).cwiseAbs().maxCoeff(), 1e-9) << image.name;
  }
}

TEST_F(CliExportTest, UndistortedModelReadsInColmapAndReprojectsAsWell) {
  if (!OnPath("colmap")) GTEST_SKIP() << "colmap is not installed (scripts/setup installs it)";
  // COLMAP's own undistorter on the same frames and model: what Gaussian splatting's
  // convert.py would have produced.
  const fs::path by_colmap = *dir_ / "colmap_undistorted";
  const CommandResult undistort = RunShell(fmt::format(
      "colmap image_undistorter --image_path {} --input_path {} --output_path {} "
      "--output_type COLMAP",
      ShellQuote((Out() / "images").string()), ShellQuote((Out() / "sparse" / "0").string()),
      ShellQuote(by_colmap.string())));
  ASSERT_EQ(undistort.exit_code, 0) << undistort;
  const fs::path text_d = *dir_ / "text_distorted", text_u = *dir_ / "text_undistorted",
                 text_c = *dir_ / "text_colmap_undistorted";
  for (const auto& [in, out] : {std::pair{Out() / "sparse" / "0", text_d},
                                std::pair{Out() / "undistorted" / "sparse" / "0", text_u},
                                std::pair{by_colmap / "sparse", text_c}}) {
    fs::create_directories(out);
    const CommandResult convert = RunShell(fmt::format(
        "colmap model_converter --input_path {} --output_path {} --output_type TXT",
        ShellQuote(in.string()), ShellQuote(out.string())));
    ASSERT_EQ(convert.exit_code, 0) << convert;
  }
  const TextModel distorted = TextModel::Read(text_d);
  const TextModel undistorted = TextModel::Read(text_u);
  ASSERT_EQ(undistorted.cameras.size(), 1u);
  const TextModel::Cam& pinhole = undistorted.cameras.begin()->second;
  EXPECT_EQ(pinhole.model, "PINHOLE");
  ASSERT_EQ(undistorted.images.size(), distorted.images.size());
  ASSERT_EQ(undistorted.points.size(), distorted.points.size());

  // The same rays in both models, so the same errors in angle; in pixels they grow where
  // undistortion stretches the image (the periphery of a barrel lens, a few percent here), for
  // COLMAP's undistorter as for ours. Anything more is a mismatch of keypoints and camera.
  const TextModel colmap = TextModel::Read(text_c);
  ASSERT_EQ(colmap.cameras.size(), 1u);
  const TextModel::Cam& colmap_pinhole = colmap.cameras.begin()->second;
  EXPECT_EQ(colmap_pinhole.model, "PINHOLE");
  // The same focal length; the size may differ by a pixel (loopsfm's rectangle runs through
  // the centres of the border pixels), the principal point with it.
  EXPECT_NEAR(pinhole.width, colmap_pinhole.width, 1);
  EXPECT_NEAR(pinhole.height, colmap_pinhole.height, 1);
  EXPECT_NEAR(pinhole.params[0], colmap_pinhole.params[0], 1e-9);
  EXPECT_NEAR(pinhole.params[1], colmap_pinhole.params[1], 1e-9);
  EXPECT_NEAR(pinhole.params[2], colmap_pinhole.params[2], 0.5 + 1e-9);
  EXPECT_NEAR(pinhole.params[3], colmap_pinhole.params[3], 0.5 + 1e-9);
  const double error_d = distorted.MeanReprojectionError();
  const double error_u = undistorted.MeanReprojectionError();
  const double error_c = colmap.MeanReprojectionError();
  std::cout << "[ info     ] reprojection error: distorted " << error_d << " px, undistorted "
            << error_u << " px, by COLMAP's image_undistorter " << error_c << " px\n";
  EXPECT_GT(error_d, 0.0);
  EXPECT_LT(error_u, 1.05 * error_d);
  EXPECT_LE(error_u, 1.001 * error_c);

  // The undistorted images show at each undistorted keypoint what the original frame shows at
  // the keypoint it came from; a mismatch of image and model would compare unrelated pixels.
  double same = 0.0, shifted = 0.0;
  int n = 0;
  for (size_t i = 0; i < undistorted.images.size(); i += 4) {
    const auto& img_u = undistorted.images[i];
    const auto& img_d = distorted.images[i];
    ASSERT_EQ(img_u.name, img_d.name);
    const cv::Mat frame_u = cv::imread((Out() / "undistorted" / "images" / img_u.name).string(),
                                       cv::IMREAD_GRAYSCALE);
    const cv::Mat frame_d = cv::imread((Out() / "images" / img_d.name).string(),
                                       cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(frame_u.empty()) << img_u.name;
    ASSERT_EQ(frame_u.cols, pinhole.width);
    ASSERT_EQ(frame_u.rows, pinhole.height);
    for (size_t k = 0; k < img_u.obs.size(); k += 10) {
      const cv::Point pu(static_cast<int>(img_u.obs[k].x), static_cast<int>(img_u.obs[k].y));
      const cv::Point pd(static_cast<int>(img_d.obs[k].x), static_cast<int>(img_d.obs[k].y));
      const cv::Point off(7, 0);
      if (!cv::Rect(0, 0, frame_u.cols - 8, frame_u.rows).contains(pu) ||
          !cv::Rect(0, 0, frame_d.cols, frame_d.rows).contains(pd)) {
        continue;
      }
      const double value_d = frame_d.at<uchar>(pd);
      same += std::abs(frame_u.at<uchar>(pu) - value_d);
      shifted += std::abs(frame_u.at<uchar>(pu + off) - value_d);
      ++n;
    }
  }
  ASSERT_GT(n, 100);
  std::cout << "[ info     ] mean grey difference at matching keypoints " << same / n
            << ", 7 px off " << shifted / n << "\n";
  EXPECT_LT(same / n, 0.5 * shifted / n);
}

TEST_F(CliExportTest, ExportRewritesFromTheRunWithoutRecomputing) {
  const std::string transforms = ReadFileBytes(Out() / "transforms.json");
  const std::string model = ReadFileBytes(Out() / "undistorted" / "sparse" / "0" / "cameras.bin");
  fs::remove(Out() / "transforms.json");
  fs::remove_all(Out() / "undistorted");
  const CommandResult result =
      RunLoopsfm({"export", Out().string(), "--format", "nerfstudio,gsplat"});
  ASSERT_EQ(result.exit_code, 0) << result;
  // The same file up to the last bit of a pose (the model was read back from its files).
  const nlohmann::json before = nlohmann::json::parse(transforms);
  const nlohmann::json after = nlohmann::json::parse(ReadFileBytes(Out() / "transforms.json"));
  ASSERT_EQ(after["frames"].size(), before["frames"].size());
  EXPECT_EQ(after["fl_x"], before["fl_x"]);
  for (size_t i = 0; i < before["frames"].size(); ++i) {
    EXPECT_EQ(after["frames"][i]["file_path"], before["frames"][i]["file_path"]);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        EXPECT_NEAR(after["frames"][i]["transform_matrix"][r][c].get<double>(),
                    before["frames"][i]["transform_matrix"][r][c].get<double>(), 1e-12);
      }
    }
  }
  EXPECT_EQ(ReadFileBytes(Out() / "undistorted" / "sparse" / "0" / "cameras.bin"), model);
  int undistorted = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(Out() / "undistorted" / "images")) {
    ++undistorted;
  }
  EXPECT_EQ(undistorted, static_cast<int>(ReadColmapModel(Out() / "sparse" / "0").NumRegImages()));
  EXPECT_FALSE(fs::exists(Out() / "undistorted.new"));
}

TEST_F(CliExportTest, BadExportRequestsExitWithCode2) {
  const CommandResult unknown = RunLoopsfm({"export", Out().string(), "--format", "ply,obj"});
  EXPECT_EQ(unknown.exit_code, 2) << unknown;
  EXPECT_NE(unknown.output.find("unknown export format 'obj'"), std::string::npos) << unknown;
  TempDir empty;
  const CommandResult no_model = RunLoopsfm({"export", empty.path().string(), "--format", "ply"});
  EXPECT_EQ(no_model.exit_code, 2) << no_model;
  EXPECT_NE(no_model.output.find("holds no model"), std::string::npos) << no_model;
  const CommandResult bad_flag = RunLoopsfm({"reconstruct", (Scene() / "images").string(), "-o",
                                             Out().string(), "--export", "colmap,splats"});
  EXPECT_EQ(bad_flag.exit_code, 2) << bad_flag;
  EXPECT_NE(bad_flag.output.find("splats"), std::string::npos) << bad_flag;
}

}  // namespace
}  // namespace loopsfm::e2e
