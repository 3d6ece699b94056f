#include <gtest/gtest.h>

#include <cstdlib>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>

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
  options.mode = KeyframeMode::kWindows;
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
  bad.mode = KeyframeMode::kWindows;
  bad.every = 0;
  EXPECT_THROW(bad.Check(), InvalidArgument);
  KeyframeOptions mixed;  // fixed windows and adaptive keyframes at once
  mixed.mode = KeyframeMode::kAdaptive;
  mixed.every = 3;
  EXPECT_THROW(mixed.Check(), InvalidArgument);
  EXPECT_THROW(ParseKeyframeMode("sometimes"), InvalidArgument);
  EXPECT_EQ(ParseKeyframeMode("adaptive"), KeyframeMode::kAdaptive);
  for (const KeyframeReason reason :
       {KeyframeReason::kWindow, KeyframeReason::kFirst, KeyframeReason::kParallax,
        KeyframeReason::kOverlap, KeyframeReason::kTrackingLost, KeyframeReason::kLast,
        KeyframeReason::kFillIn}) {
    EXPECT_EQ(ParseKeyframeReason(KeyframeReasonName(reason)), reason);
  }
  EXPECT_FALSE(ParseKeyframeReason("because").has_value());
}

// Frames made in memory: two textured layers sliding sideways, the far one (top half) at
// `far_px` and the near one (bottom half) at `near_px` pixels per frame, as a camera walking
// past a wall with another behind it sees them. Equal speeds look like a turn of the camera
// (no parallax); different speeds are parallax. Frames in `blurred` are motion-blurred.
class SlidingLayers : public FrameSource {
 public:
  SlidingLayers(int num_frames, double far_px, double near_px, double fps,
                std::pair<int, int> blurred = {-1, -1})
      : num_frames_(num_frames), far_px_(far_px), near_px_(near_px), blurred_(blurred) {
    info_.kind = SourceKind::kVideo;
    info_.fps = fps;
    info_.expected_frames = num_frames;
    far_ = Texture(1, 4000);
    near_ = Texture(2, 4000);
  }
  std::optional<RawFrame> Next() override {
    if (next_ >= num_frames_) return std::nullopt;
    const int i = next_++;
    cv::Mat frame(kHeight, kWidth, CV_8UC3);
    Slide(far_, far_px_ * i).rowRange(0, kHeight / 2).copyTo(frame.rowRange(0, kHeight / 2));
    Slide(near_, near_px_ * i)
        .rowRange(kHeight / 2, kHeight)
        .copyTo(frame.rowRange(kHeight / 2, kHeight));
    if (i >= blurred_.first && i <= blurred_.second) {
      cv::blur(frame, frame, cv::Size(15, 1));
    }
    return RawFrame{i, VideoFrameName(i), frame};
  }
  bool Skip() override { return next_++ < num_frames_; }

  static constexpr int kWidth = 320, kHeight = 240;

 private:
  static cv::Mat Texture(int seed, int width) {
    cv::Mat noise(kHeight, width, CV_8UC3);
    cv::RNG rng(seed);
    rng.fill(noise, cv::RNG::UNIFORM, 0, 255);
    cv::GaussianBlur(noise, noise, cv::Size(0, 0), 2.0);
    cv::normalize(noise, noise, 0, 255, cv::NORM_MINMAX);
    return noise;
  }
  // The frame-wide window of `texture` starting `offset` pixels in (sub-pixel: bilinear).
  static cv::Mat Slide(const cv::Mat& texture, double offset) {
    const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, -offset, 0, 1, 0);
    cv::Mat out;
    cv::warpAffine(texture, out, m, cv::Size(kWidth, kHeight), cv::INTER_LINEAR);
    return out;
  }
  int num_frames_, next_ = 0;
  double far_px_, near_px_;
  std::pair<int, int> blurred_;
  cv::Mat far_, near_;
};

std::vector<Keyframe> AdaptiveKeyframes(FrameSource& source, KeyframeSummary* summary = nullptr,
                                        double min_tracked_fraction = 0.8) {
  KeyframeOptions options;
  options.mode = KeyframeMode::kAdaptive;
  options.adaptive.min_tracked_fraction = min_tracked_fraction;
  KeyframeSelector selector(source, options);
  std::vector<Keyframe> keyframes;
  while (auto keyframe = selector.Next()) keyframes.push_back(std::move(*keyframe));
  if (summary) *summary = selector.Summary();
  if (std::getenv("LOOPSFM_TEST_VERBOSE")) {
    for (const Keyframe& k : keyframes) {
      std::cerr << k.frame.source_index << ":" << KeyframeReasonName(k.reason) << " ";
    }
    std::cerr << "\n";
  }
  return keyframes;
}

int CountReason(const std::vector<Keyframe>& keyframes, KeyframeReason reason) {
  return static_cast<int>(std::count_if(keyframes.begin(), keyframes.end(),
                                        [&](const Keyframe& k) { return k.reason == reason; }));
}

// A clip shorter than the look-back: its first frame, and its last when the view moved on.
TEST(AdaptiveKeyframes, ShortClipKeepsItsEndsWhenTheViewMoved) {
  SlidingLayers still(3, 0.0, 0.0, 30.0), moving(3, 100.0, 200.0, 30.0);
  EXPECT_EQ(AdaptiveKeyframes(still).size(), 1u);
  const std::vector<Keyframe> keyframes = AdaptiveKeyframes(moving);
  ASSERT_EQ(keyframes.size(), 2u);
  EXPECT_EQ(keyframes[0].frame.source_index, 0);
  EXPECT_EQ(keyframes[1].reason, KeyframeReason::kLast);
}

TEST(AdaptiveKeyframes, StandingStillKeepsOneFrame) {
  SlidingLayers source(60, 0.0, 0.0, 30.0);
  const std::vector<Keyframe> keyframes = AdaptiveKeyframes(source);
  ASSERT_EQ(keyframes.size(), 1u);
  EXPECT_EQ(keyframes[0].reason, KeyframeReason::kFirst);
}

// Both layers at one speed: a turn, no parallax. Keyframes come only as the view moves on
// (the tracked corners leave the frame), about every fifth of the frame width.
TEST(AdaptiveKeyframes, TurningGivesKeyframesByOverlapNotParallax) {
  SlidingLayers source(120, 4.0, 4.0, 30.0);  // 480 px: one and a half frame widths
  const std::vector<Keyframe> keyframes = AdaptiveKeyframes(source);
  EXPECT_EQ(CountReason(keyframes, KeyframeReason::kParallax), 0);
  EXPECT_GE(CountReason(keyframes, KeyframeReason::kOverlap), 4);
  EXPECT_LE(keyframes.size(), 12u);
  for (size_t i = 1; i < keyframes.size(); ++i) {
    EXPECT_GT(keyframes[i].frame.source_index, keyframes[i - 1].frame.source_index);
  }
}

// Layers at different speeds: parallax (the overlap rule relaxed, so that parallax decides).
// Twice the difference gives more keyframes, and the same motion filmed at twice the frame
// rate gives about the same keyframes.
TEST(AdaptiveKeyframes, ParallaxGivesKeyframesIndependentOfFrameRate) {
  SlidingLayers slow(90, 0.5, 1.5, 30.0), fast(90, 0.5, 2.5, 30.0), fast60(180, 0.25, 0.75, 60.0);
  const std::vector<Keyframe> slow_keys = AdaptiveKeyframes(slow, nullptr, 0.3);
  const std::vector<Keyframe> fast_keys = AdaptiveKeyframes(fast, nullptr, 0.3);
  const std::vector<Keyframe> fast60_keys = AdaptiveKeyframes(fast60, nullptr, 0.3);
  ASSERT_GE(slow_keys.size(), 2u);
  EXPECT_GE(CountReason(slow_keys, KeyframeReason::kParallax), 1);
  EXPECT_GT(fast_keys.size(), slow_keys.size());
  EXPECT_NEAR(static_cast<double>(fast60_keys.size()), static_cast<double>(slow_keys.size()), 1.0);
  // The 60 fps keyframes sit where the 30 fps ones do, in time (two 60 fps frames a 30 fps one).
  const size_t common = std::min(fast60_keys.size(), slow_keys.size());
  ASSERT_GE(common, 2u);
  for (size_t i = 0; i < common; ++i) {
    EXPECT_NEAR(fast60_keys[i].frame.source_index / 2.0, slow_keys[i].frame.source_index, 3.0);
  }
}

// A blurred stretch: no blurred frame is kept while sharp ones are near, and the summary
// marks the stretch.
TEST(AdaptiveKeyframes, BlurredFramesAreNotKeptWhenSharpOnesAreClose) {
  SlidingLayers source(150, 1.0, 3.0, 30.0, {50, 60});
  KeyframeSummary summary;
  const std::vector<Keyframe> keyframes = AdaptiveKeyframes(source, &summary);
  EXPECT_EQ(summary.frames_read, 150);
  EXPECT_EQ(summary.keyframes, static_cast<int>(keyframes.size()));
  for (int i = 50; i <= 60; ++i) {
    EXPECT_NE(std::find(summary.blurred.begin(), summary.blurred.end(), i), summary.blurred.end())
        << "frame " << i << " is blurred";
  }
  for (const Keyframe& keyframe : keyframes) {
    const int index = keyframe.frame.source_index;
    EXPECT_FALSE(index >= 50 && index <= 60) << "blurred frame " << index << " kept ("
                                              << KeyframeReasonName(keyframe.reason) << ")";
  }
  EXPECT_GE(keyframes.size(), 3u);
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
