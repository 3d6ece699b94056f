#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "loopsfm/util/errors.h"
#include "loopsfm/video/frame_source.h"
#include "loopsfm/video/keyframes.h"

namespace loopsfm {
namespace {
namespace fs = std::filesystem;

fs::path FreshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("loopsfm_video_test_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// A textured frame; odd frames are blurred when `blur_odd`.
cv::Mat TestFrame(int index, bool blur) {
  cv::Mat image(120, 160, CV_8UC3);
  cv::RNG rng(1234);  // same texture every frame, shifted by index
  rng.fill(image, cv::RNG::UNIFORM, 0, 255);
  cv::resize(image, image, cv::Size(), 1.0, 1.0);
  cv::Mat shifted;
  const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, index, 0, 1, 0);
  cv::warpAffine(image, shifted, m, image.size(), cv::INTER_NEAREST, cv::BORDER_REFLECT);
  if (blur) cv::GaussianBlur(shifted, shifted, cv::Size(9, 9), 3.0);
  return shifted;
}

fs::path WriteVideo(const fs::path& dir, int num_frames, bool blur_odd) {
  const fs::path path = dir / "clip.avi";
  cv::VideoWriter writer(path.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'),
                         10, cv::Size(160, 120));
  EXPECT_TRUE(writer.isOpened());
  for (int i = 0; i < num_frames; ++i) writer.write(TestFrame(i, blur_odd && i % 2 == 1));
  return path;
}

TEST(FrameSource, VideoFramesAreNamedByIndex) {
  const fs::path video = WriteVideo(FreshDir("names"), 7, false);
  auto source = OpenFrameSource(video);
  EXPECT_EQ(source->Info().kind, SourceKind::kVideo);
  int count = 0;
  while (auto frame = source->Next()) {
    EXPECT_EQ(frame->source_index, count);
    EXPECT_EQ(frame->name, VideoFrameName(count));
    EXPECT_EQ(frame->image.cols, 160);
    ++count;
  }
  EXPECT_EQ(count, 7);
  EXPECT_EQ(VideoFrameName(12), "frame_000012.png");
}

// A phone's portrait video: landscape frames with a 90 degree rotation flag. Frames come
// out upright (portrait), turned as the flag says.
TEST(FrameSource, RotationFlagTurnsFramesUpright) {
  if (std::system("ffmpeg -version > /dev/null 2>&1") != 0) GTEST_SKIP() << "ffmpeg not found";
  const fs::path dir = FreshDir("rotation");
  const fs::path clip = WriteVideo(dir, 3, false);
  const fs::path landscape = dir / "landscape.mp4", rotated = dir / "portrait.mp4";
  // ffmpeg writes the rotation flag when copying a stream, not when encoding one.
  const std::string command = "ffmpeg -loglevel error -y -i '" + clip.string() +
                              "' -c:v mpeg4 -q:v 2 '" + landscape.string() +
                              "' && ffmpeg -loglevel error -y -i '" + landscape.string() +
                              "' -c copy -metadata:s:v:0 rotate=90 '" + rotated.string() + "'";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  auto source = OpenFrameSource(rotated);
  const std::optional<RawFrame> frame = source->Next();
  ASSERT_TRUE(frame.has_value());
  EXPECT_EQ(frame->image.cols, 120);
  EXPECT_EQ(frame->image.rows, 160);
  // The picture is the original turned by 90 degrees (clockwise, as the flag is read), not
  // merely resized.
  // Compared at 1/8 size: the per-pixel noise texture does not survive two lossy codecs.
  auto coarse = [](const cv::Mat& image) {
    cv::Mat small;
    cv::resize(image, small, cv::Size(image.cols / 8, image.rows / 8), 0, 0, cv::INTER_AREA);
    return small;
  };
  cv::Mat clockwise, counter;
  cv::rotate(TestFrame(0, false), clockwise, cv::ROTATE_90_CLOCKWISE);
  cv::rotate(TestFrame(0, false), counter, cv::ROTATE_90_COUNTERCLOCKWISE);
  const cv::Mat decoded = coarse(frame->image);
  const double error_cw = cv::norm(decoded, coarse(clockwise), cv::NORM_L1);
  const double error_ccw = cv::norm(decoded, coarse(counter), cv::NORM_L1);
  EXPECT_LT(std::min(error_cw, error_ccw), 0.5 * std::max(error_cw, error_ccw))
      << error_cw << " " << error_ccw;
}

TEST(Keyframes, SharpestFrameOfEachWindowIsKept) {
  const fs::path video = WriteVideo(FreshDir("sharp"), 9, /*blur_odd=*/true);
  auto source = OpenFrameSource(video);
  KeyframeOptions options;
  options.every = 2;
  KeyframeSelector selector(*source, options);
  std::vector<int> kept;
  while (auto keyframe = selector.Next()) kept.push_back(keyframe->frame.source_index);
  // Windows {0,1} {2,3} {4,5} {6,7} {8}: the even (sharp) frame wins each window.
  EXPECT_EQ(kept, (std::vector<int>{0, 2, 4, 6, 8}));
}

TEST(Keyframes, BlurLowersSharpness) {
  EXPECT_GT(FrameSharpness(TestFrame(0, false)), 2.0 * FrameSharpness(TestFrame(0, true)));
  KeyframeOptions bad;
  bad.every = 0;
  EXPECT_THROW(bad.Check(), InvalidArgument);
}

TEST(FrameSource, FolderIsSortedAndUnreadableImagesAreSkipped) {
  const fs::path dir = FreshDir("folder");
  cv::imwrite((dir / "b.png").string(), TestFrame(1, false));
  cv::imwrite((dir / "a.png").string(), TestFrame(0, false));
  std::ofstream(dir / "c.jpg") << "this is not a jpeg";
  std::ofstream(dir / "notes.txt") << "ignored";
  auto source = OpenFrameSource(dir);
  std::vector<std::string> names;
  while (auto frame = source->Next()) names.push_back(frame->name);
  EXPECT_EQ(names, (std::vector<std::string>{"a.png", "b.png"}));
  EXPECT_EQ(source->NumSkipped(), 1);
}

TEST(FrameSource, BadInputsGiveClearErrors) {
  const fs::path dir = FreshDir("bad");
  EXPECT_THROW(OpenFrameSource(dir / "missing.mp4"), InputError);
  EXPECT_THROW(OpenFrameSource(dir), InputError);  // empty folder
  std::ofstream(dir / "notes.mp4") << "plain text, not a video";
  EXPECT_THROW(
      {
        auto source = OpenFrameSource(dir / "notes.mp4");
        source->Next();
      },
      InputError);
  cv::imwrite((dir / "single.png").string(), TestFrame(0, false));
  try {
    OpenFrameSource(dir / "single.png");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("single image"), std::string::npos);
  }
}

TEST(FrameSource, TruncatedVideoYieldsTheFramesBeforeTheCut) {
  const fs::path dir = FreshDir("truncated");
  const fs::path video = WriteVideo(dir, 20, false);
  const auto size = fs::file_size(video);
  fs::resize_file(video, size / 2);
  auto source = OpenFrameSource(video);
  int count = 0;
  while (source->Next()) ++count;
  EXPECT_GT(count, 0);
  EXPECT_LT(count, 20);
}

TEST(FrameSource, VideoWithHeaderOnlyHasNoDecodableFrame) {
  const fs::path dir = FreshDir("headeronly");
  const fs::path video = WriteVideo(dir, 5, false);
  fs::resize_file(video, 300);  // keeps the container header, cuts every frame
  EXPECT_THROW(
      {
        auto source = OpenFrameSource(video);
        while (source->Next()) {
        }
      },
      InputError);
}

}  // namespace
}  // namespace loopsfm
