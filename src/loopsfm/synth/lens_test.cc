// Synthetic frames through a distorting lens (SynthOptions::lens).

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/synth/lens.h"
#include "loopsfm/synth/render.h"
#include "loopsfm/synth/synth_test_util.h"
#include "loopsfm/synth/synthetic_scene.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using synth_test::InImage;
using synth_test::Project;
using synth_test::SmallOptions;
using synth_test::TempDir;

// An action camera's barrel distortion on the small street scene (320 x 240, f = 288 px).
SynthOptions BarrelOptions() {
  SynthOptions options = SmallOptions("street");
  options.lens.model = CameraModelId::kSimpleRadial;
  options.lens.k1 = -0.15;
  return options;
}

std::string ReadText(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

TEST(SynthLens, CameraTakesTheModelsParametersInColmapOrder) {
  const Camera pinhole = MakeScene(SynthOptions{}).camera;
  EXPECT_EQ(pinhole.model_id, CameraModelId::kPinhole);
  EXPECT_EQ(pinhole.params, (std::vector<double>{576, 576, 320, 240}));

  LensOptions lens;
  lens.model = CameraModelId::kSimpleRadial;
  lens.k1 = -0.15;
  EXPECT_EQ(MakeSynthCamera(lens, 640, 360, 0.9).params,
            (std::vector<double>{576, 320, 180, -0.15}));
  lens.model = CameraModelId::kOpenCV;
  lens.k2 = 0.02;
  lens.p1 = 0.001;
  lens.p2 = -0.002;
  EXPECT_EQ(MakeSynthCamera(lens, 640, 360, 0.9).params,
            (std::vector<double>{576, 576, 320, 180, -0.15, 0.02, 0.001, -0.002}));
  lens.model = CameraModelId::kFullOpenCV;
  lens.k3 = 0.003;
  lens.k4 = 0.01;
  lens.k5 = 0.002;
  lens.k6 = 0.001;
  EXPECT_EQ(MakeSynthCamera(lens, 640, 360, 0.9).params,
            (std::vector<double>{576, 576, 320, 180, -0.15, 0.02, 0.001, -0.002, 0.003, 0.01,
                                 0.002, 0.001}));
  LensOptions fisheye;
  fisheye.model = CameraModelId::kOpenCVFisheye;
  fisheye.k1 = 0.05;
  fisheye.k2 = -0.01;
  fisheye.k3 = 0.002;
  fisheye.k4 = -0.0005;
  EXPECT_EQ(MakeSynthCamera(fisheye, 640, 360, 0.5).params,
            (std::vector<double>{320, 320, 320, 180, 0.05, -0.01, 0.002, -0.0005}));
}

TEST(SynthLens, CheckRejectsUnusedCoefficientsAndLensesThatFoldOver) {
  auto expect_rejected = [](const SynthOptions& bad, const std::string& words) {
    try {
      bad.Check();
      ADD_FAILURE() << "accepted options that should fail with '" << words << "'";
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  EXPECT_NO_THROW(BarrelOptions().Check());
  SynthOptions bad = BarrelOptions();
  bad.lens.k2 = 0.02;
  expect_rejected(bad, "camera model SIMPLE_RADIAL does not take k2 (its parameters: f, cx, cy, k)");
  bad = SynthOptions{};
  bad.lens.p1 = 0.001;
  expect_rejected(bad, "camera model PINHOLE does not take p1");
  // r_d = r (1 - 0.6 r^2) peaks at r_d = 0.50; the image corner is at r_d = 0.69.
  bad = BarrelOptions();
  bad.lens.k1 = -0.6;
  expect_rejected(bad, "the SIMPLE_RADIAL lens cannot be inverted at image point");
  // The corner of a 320 x 240 fisheye frame with f = 64 px is theta_d = 3.1 rad from the axis.
  bad = SmallOptions("street");
  bad.lens.model = CameraModelId::kOpenCVFisheye;
  bad.focal_length_factor = 0.2;
  expect_rejected(bad, "the OPENCV_FISHEYE lens cannot be inverted");
  bad.focal_length_factor = 0.9;
  EXPECT_NO_THROW(bad.Check());
}

// A surface point seen through a pixel of the undistorted (pinhole) frame projects through the
// lens onto a pixel whose ray hits that very point, and the distorted frame shows there what
// the pinhole frame shows at the point: the frame is truly distorted by the model.
TEST(SynthLens, SurfacePointsProjectThroughTheModelOntoThePixelThatSeesThem) {
  const SynthOptions distorted_options = BarrelOptions();
  SynthOptions pinhole_options = distorted_options;
  pinhole_options.lens = LensOptions{};
  const SyntheticScene distorted = MakeScene(distorted_options);
  const SyntheticScene pinhole = MakeScene(pinhole_options);
  const int frame = 5;
  ASSERT_EQ(distorted.world_from_cam[frame].translation, pinhole.world_from_cam[frame].translation);
  const cv::Mat distorted_image = RenderFrame(distorted, frame);
  const cv::Mat pinhole_image = RenderFrame(pinhole, frame);
  cv::Mat distorted_grey, pinhole_grey;
  cv::cvtColor(distorted_image, distorted_grey, cv::COLOR_BGR2GRAY);
  cv::cvtColor(pinhole_image, pinhole_grey, cv::COLOR_BGR2GRAY);
  distorted_grey.convertTo(distorted_grey, CV_32F);
  pinhole_grey.convertTo(pinhole_grey, CV_32F);
  // Grey level of the distorted frame at a point in COLMAP image coordinates (bilinear).
  auto distorted_at = [&](const Eigen::Vector2d& xy) {
    cv::Mat patch;
    cv::getRectSubPix(distorted_grey, cv::Size(1, 1),
                      cv::Point2f(static_cast<float>(xy.x() - 0.5), static_cast<float>(xy.y() - 0.5)),
                      patch);
    return static_cast<double>(patch.at<float>(0, 0));
  };

  int num_points = 0;
  double max_shift = 0.0, through_lens = 0.0, without_lens = 0.0;
  for (int row = 2; row < pinhole.camera.height; row += 5) {
    for (int col = 3; col < pinhole.camera.width; col += 5) {
      const Eigen::Vector2d pixel(col + 0.5, row + 0.5);
      const auto seen = CastPixelRay(pinhole, frame, pixel);
      if (!seen) continue;
      const Eigen::Vector3d& point = seen->point_in_world;
      const Eigen::Vector2d through = Project(distorted, frame, point);
      if (!InImage(distorted, through)) continue;
      const auto hit = CastPixelRay(distorted, frame, through);
      ASSERT_TRUE(hit.has_value());
      EXPECT_LT((hit->point_in_world - point).norm(), 1e-6 * seen->distance);
      max_shift = std::max(max_shift, (through - pixel).norm());
      ++num_points;
      const double expected = pinhole_grey.at<float>(row, col);
      through_lens += std::abs(distorted_at(through) - expected);
      without_lens += std::abs(distorted_at(pixel) - expected);
    }
  }
  ASSERT_GT(num_points, 1000);
  // Barrel distortion pulls the image corners about 14 pixels inwards (r_d = r (1 - 0.15 r^2)
  // at r = 0.69 is 0.64, times f = 288).
  EXPECT_GT(max_shift, 12.0);
  EXPECT_LT(max_shift, 16.0);
  // Mean grey-level difference to the pinhole frame. Measured: 0.61 through the lens (what is
  // left is the bilinear interpolation of the texture), 16.9 at the same pixel.
  EXPECT_LT(through_lens / num_points, 1.5);
  EXPECT_GT(without_lens, 10.0 * through_lens);
}

// Lenses without distortion (SIMPLE_PINHOLE, zero coefficients) render the PINHOLE frame bit for
// bit, through the undistortion code.
TEST(SynthLens, ZeroDistortionRendersThePinholeFrameBitForBit) {
  const SynthOptions options = SmallOptions("street");
  const cv::Mat pinhole = RenderFrame(MakeScene(options), 4);
  for (const CameraModelId model :
       {CameraModelId::kSimplePinhole, CameraModelId::kSimpleRadial, CameraModelId::kOpenCV,
        CameraModelId::kFullOpenCV}) {
    SynthOptions lens_options = options;
    lens_options.lens.model = model;
    const SyntheticScene scene = MakeScene(lens_options);
    EXPECT_EQ(scene.camera.model_id, model);
    EXPECT_EQ(cv::norm(RenderFrame(scene, 4), pinhole, cv::NORM_INF), 0.0) << CameraModelName(model);
  }
}

TEST(SynthLens, IntrinsicsFileHoldsTheLensAndGroundTruthIsUnchanged) {
  SynthOptions options = BarrelOptions();
  options.lens.model = CameraModelId::kOpenCV;
  options.lens.k2 = 0.02;
  options.lens.p1 = 0.0007;
  options.width = 64;
  options.height = 48;
  options.num_frames = 3;
  const TempDir distorted_dir("lens_distorted"), pinhole_dir("lens_pinhole");
  RenderSyntheticScene(options, distorted_dir.path());
  const Camera camera = ReadIntrinsicsFile(distorted_dir.path() / "intrinsics.txt");
  EXPECT_EQ(camera.model_id, CameraModelId::kOpenCV);
  EXPECT_EQ(camera.params, MakeScene(options).camera.params);  // written with all digits
  EXPECT_EQ(camera.params, (std::vector<double>{57.6, 57.6, 32, 24, -0.15, 0.02, 0.0007, 0}));
  options.lens = LensOptions{};
  RenderSyntheticScene(options, pinhole_dir.path());
  EXPECT_EQ(ReadText(distorted_dir.path() / "groundtruth.txt"),
            ReadText(pinhole_dir.path() / "groundtruth.txt"));
}

}  // namespace
}  // namespace loopsfm
