// Degradations of rendered frames: range specs, noise, motion blur, low texture, dark frames,
// JPEG output.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/synth/frame_degradation.h"
#include "loopsfm/synth/render.h"
#include "loopsfm/synth/synth_test_util.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using synth_test::CountSift;
using synth_test::SmallOptions;
using synth_test::TempDir;

cv::Mat Gray(const cv::Mat& image) {
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

double StdDev(const cv::Mat& image) {
  cv::Scalar mean, deviation;
  cv::meanStdDev(image, mean, deviation);
  return deviation[0];
}

// Variance of the Laplacian of the grey image, a common sharpness measure.
double Sharpness(const cv::Mat& image) {
  cv::Mat laplacian;
  cv::Laplacian(Gray(image), laplacian, CV_64F);
  const double deviation = StdDev(laplacian);
  return deviation * deviation;
}

// Mean squared derivative of the grey image along x (dx = 1) or y.
double GradientEnergy(const cv::Mat& image, int dx) {
  cv::Mat derivative;
  cv::Sobel(Gray(image), derivative, CV_64F, dx, 1 - dx);
  return cv::mean(derivative.mul(derivative))[0];
}

template <typename F>
std::string ErrorOf(F&& f) {
  try {
    f();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(FrameRanges, ParseListsAndNameTheBadPart) {
  const std::vector<FrameRange> ranges = ParseFrameRanges("200-220,5,7-7");
  ASSERT_EQ(ranges.size(), 3u);
  EXPECT_EQ(ranges[0].first, 200);
  EXPECT_EQ(ranges[0].last, 220);
  EXPECT_EQ(ranges[1].first, 5);
  EXPECT_EQ(ranges[1].last, 5);
  EXPECT_TRUE(ranges[2].Contains(7));
  EXPECT_FALSE(ranges[0].Contains(221));
  const std::vector<BlurRange> blur = ParseBlurRanges("120-140:15,300-310:2.5");
  ASSERT_EQ(blur.size(), 2u);
  EXPECT_EQ(blur[1].frames.first, 300);
  EXPECT_EQ(blur[1].frames.last, 310);
  EXPECT_EQ(blur[1].length_pixels, 2.5);

  for (const std::string bad : {"12-", "-3-4", "20-10", "a-b", "1.5-3", "1-2;3-4", ""}) {
    const std::string spec = "1-2," + bad;
    const std::string error = ErrorOf([&] { ParseFrameRanges(spec); });
    EXPECT_NE(error.find("'" + bad + "' in '" + spec + "'"), std::string::npos) << error;
    EXPECT_NE(error.find("write FIRST-LAST"), std::string::npos) << error;
  }
  EXPECT_NE(ErrorOf([] { ParseFrameRanges(""); }).find("empty frame range list"),
            std::string::npos);
  for (const std::string bad : {"120-140", "120-140:", "120-140:0.5", "1-2:x", "1-2:3:4",
                                "1-2:500"}) {
    const std::string error = ErrorOf([&] { ParseBlurRanges(bad); });
    EXPECT_NE(error.find("bad blur range '" + bad + "'"), std::string::npos) << error;
    EXPECT_NE(error.find("write FIRST-LAST:LENGTH"), std::string::npos) << error;
  }
}

TEST(FrameDegradation, NoiseHasTheRequestedSigmaAndIsSeeded) {
  FrameDegradationOptions options;
  options.noise_sigma = 3.0;
  const cv::Mat flat(150, 200, CV_8UC3, cv::Scalar::all(128));
  auto degraded = [&](int frame, uint64_t seed) {
    cv::Mat image = flat.clone();
    DegradeFrame(options, frame, Eigen::Vector2d::Zero(), seed, &image);
    return image;
  };
  const cv::Mat noisy = degraded(7, 42);
  cv::Mat difference;
  noisy.convertTo(difference, CV_64FC3, 1.0, -128.0);
  const cv::Mat samples = difference.reshape(1);
  EXPECT_NEAR(StdDev(samples), 3.0, 0.3);
  EXPECT_LT(std::abs(cv::mean(samples)[0]), 0.05);
  EXPECT_EQ(cv::norm(noisy, degraded(7, 42), cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(noisy, degraded(8, 42), cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(noisy, degraded(7, 43), cv::NORM_INF), 0.0);
}

// Motion blur lowers the sharpness of the frames of its range only, and along the image
// motion (horizontal where the camera walks past a facade) much more than across it.
TEST(FrameDegradation, MotionBlurLowersSharpnessAlongTheMotionInItsFramesOnly) {
  SynthOptions options = SmallOptions("street");
  options.num_frames = 150;
  options.degradation.motion_blur = {{{3, 6}, 9.0}};
  const SyntheticScene scene = MakeScene(options);
  // The camera walks east past the south facade looking north: the image moves left.
  const Eigen::Vector2d motion = ImageMotion(scene, 4);
  EXPECT_LT(motion.x(), -1.0);
  EXPECT_LT(std::abs(motion.y()), 0.2 * std::abs(motion.x()));
  for (int frame = 2; frame <= 7; ++frame) {
    SCOPED_TRACE(frame);
    const cv::Mat sharp = RenderFrame(scene, frame);
    const cv::Mat image = RenderDegradedFrame(scene, frame);
    if (frame == 2 || frame == 7) {
      EXPECT_EQ(cv::norm(image, sharp, cv::NORM_INF), 0.0);
      continue;
    }
    EXPECT_LT(Sharpness(image), 0.35 * Sharpness(sharp));
    const double along = GradientEnergy(image, 1) / GradientEnergy(sharp, 1);
    const double across = GradientEnergy(image, 0) / GradientEnergy(sharp, 0);
    EXPECT_LT(along, 0.5 * across);
  }
}

TEST(FrameDegradation, LowTextureWashesOutFeaturesAndDarkFramesAreBlack) {
  SynthOptions options = SmallOptions("street");
  options.degradation.low_texture = {{2, 3}};  // at the default contrast, 0.25
  options.degradation.dark = {{5, 5}};
  const SyntheticScene scene = MakeScene(options);
  const cv::Mat sharp = RenderFrame(scene, 2);
  const cv::Mat washed = RenderDegradedFrame(scene, 2);
  const double deviation = StdDev(Gray(sharp));
  EXPECT_NEAR(StdDev(Gray(washed)), 0.25 * deviation, 0.5 + 0.02 * deviation);
  EXPECT_NEAR(cv::mean(Gray(washed))[0], cv::mean(Gray(sharp))[0], 1.0);
  const int features = CountSift(sharp), washed_features = CountSift(washed);
  EXPECT_LT(washed_features, 0.2 * features);
  RecordProperty("sift_sharp", features);
  RecordProperty("sift_low_texture", washed_features);
  EXPECT_EQ(cv::norm(RenderDegradedFrame(scene, 5), cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(RenderDegradedFrame(scene, 4), RenderFrame(scene, 4), cv::NORM_INF), 0.0);
}

// With a JPEG quality, images are written as .jpg named so in the ground truth, and video
// frames go through JPEG before the video encoder.
TEST(FrameDegradation, JpegQualityWritesJpgFramesAndCompressesVideoFrames) {
  SynthOptions options = SmallOptions("street");
  options.num_frames = 3;
  options.width = 96;
  options.height = 64;
  options.degradation.jpeg_quality = 75;
  options.degradation.noise_sigma = 2.0;
  const TempDir temp("jpeg");
  const std::filesystem::path& dir = temp.path();
  RenderSyntheticScene(options, dir);
  const SyntheticScene scene = MakeScene(options);
  const std::vector<TrajectoryEntry> truth = ReadTrajectoryFile(dir / "groundtruth.txt");
  ASSERT_EQ(truth.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(truth[i].name, "frame_00000" + std::to_string(i) + ".jpg");
    const cv::Mat written = cv::imread((dir / "images" / truth[i].name).string());
    ASSERT_FALSE(written.empty());
    const cv::Mat degraded = RenderDegradedFrame(scene, i);
    EXPECT_EQ(cv::norm(written, JpegRoundTrip(degraded, 75), cv::NORM_INF), 0.0);
    const double psnr = cv::PSNR(written, degraded);
    EXPECT_GT(psnr, 25.0);
    EXPECT_LT(psnr, 45.0);
  }
  // A later run without JPEG replaces the .jpg frames.
  options.degradation.jpeg_quality = 0;
  RenderSyntheticScene(options, dir);
  EXPECT_FALSE(std::filesystem::exists(dir / "images" / "frame_000000.jpg"));
  EXPECT_TRUE(std::filesystem::exists(dir / "images" / "frame_000000.png"));

  options.video = true;
  options.num_frames = 6;
  options.degradation.jpeg_quality = 15;
  options.degradation.noise_sigma = 0.0;
  RenderSyntheticScene(options, dir);
  const SyntheticScene video_scene = MakeScene(options);
  cv::VideoCapture capture((dir / "video.mp4").string(), cv::CAP_FFMPEG);
  ASSERT_TRUE(capture.isOpened());
  int frames = 0;
  for (cv::Mat frame; capture.read(frame); ++frames) {
    if (frames != 2) continue;
    const cv::Mat rendered = RenderFrame(video_scene, 2);
    // The decoded frame is the JPEG frame re-encoded: nearer to it than to the rendering.
    EXPECT_GT(cv::PSNR(frame, JpegRoundTrip(rendered, 15)), cv::PSNR(frame, rendered) + 1.0);
  }
  EXPECT_EQ(frames, 6);
  EXPECT_EQ(ReadTrajectoryFile(dir / "groundtruth.txt").front().name, "frame_000000.png");
}

}  // namespace
}  // namespace loopsfm
