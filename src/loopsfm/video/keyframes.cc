#include "loopsfm/video/keyframes.h"

#include <opencv2/imgproc.hpp>

#include "loopsfm/util/errors.h"

namespace loopsfm {

void KeyframeOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(every >= 1, "--every must be at least 1, got {}", every);
}

double FrameSharpness(const cv::Mat& image) {
  cv::Mat grey, dx, dy;
  if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = image;
  }
  // 3x3 Sobel of 8-bit pixels fits 16 bits exactly: half the memory of floats (an 8K frame).
  cv::Sobel(grey, dx, CV_16S, 1, 0);
  cv::Sobel(grey, dy, CV_16S, 0, 1);
  return (cv::sum(cv::abs(dx))[0] + cv::sum(cv::abs(dy))[0]) / static_cast<double>(grey.total());
}

KeyframeSelector::KeyframeSelector(FrameSource& source, const KeyframeOptions& options)
    : source_(source), options_(options) {
  options_.Check();
}

std::optional<Keyframe> KeyframeSelector::Next() {
  if (options_.every == 1 || !options_.sharpest) {
    std::optional<RawFrame> frame = source_.Next();
    if (!frame) return std::nullopt;
    for (int i = 1; i < options_.every && source_.Skip(); ++i) {
    }
    Keyframe keyframe{std::move(*frame), 0.0};
    keyframe.sharpness = FrameSharpness(keyframe.frame.image);
    return keyframe;
  }
  std::optional<Keyframe> best;
  for (int i = 0; i < options_.every; ++i) {
    std::optional<RawFrame> frame = source_.Next();
    if (!frame) break;
    const double sharpness = FrameSharpness(frame->image);
    if (!best || sharpness > best->sharpness) best = Keyframe{std::move(*frame), sharpness};
  }
  return best;
}

}  // namespace loopsfm
