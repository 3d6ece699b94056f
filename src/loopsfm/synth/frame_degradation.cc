#include "loopsfm/synth/frame_degradation.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <string_view>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Longest blur kernel accepted, in pixels.
constexpr double kMaxBlurLength = 200.0;

template <typename T>
bool ParseNumber(std::string_view text, T* value) {
  if (text.empty()) return false;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), *value);
  return error == std::errc() && end == text.data() + text.size();
}

// "FIRST-LAST" or "FIRST" with 0 <= FIRST <= LAST.
bool ParseRange(std::string_view text, FrameRange* range) {
  const size_t dash = text.find('-');
  if (dash == std::string_view::npos) {
    if (!ParseNumber(text, &range->first)) return false;
    range->last = range->first;
  } else if (!ParseNumber(text.substr(0, dash), &range->first) ||
             !ParseNumber(text.substr(dash + 1), &range->last)) {
    return false;
  }
  return range->first >= 0 && range->first <= range->last;
}

// The comma-separated parts of `spec`, each turned into a T by `parse` (false: bad part).
template <typename T, typename Parse>
std::vector<T> ParseList(const std::string& spec, Parse&& parse, const char* what,
                         const char* form) {
  LOOPSFM_REQUIRE_OPTION(!spec.empty(), "empty {} list; write {}", what, form);
  std::vector<T> values;
  std::string_view rest = spec;
  while (true) {
    const size_t comma = rest.find(',');
    const std::string_view part = rest.substr(0, comma);
    T value;
    LOOPSFM_REQUIRE_OPTION(parse(part, &value), "bad {} '{}' in '{}'; write {}", what, part, spec,
                           form);
    values.push_back(value);
    if (comma == std::string_view::npos) break;
    rest = rest.substr(comma + 1);
  }
  return values;
}

bool Covers(const std::vector<FrameRange>& ranges, int frame) {
  return std::any_of(ranges.begin(), ranges.end(),
                     [frame](const FrameRange& r) { return r.Contains(frame); });
}

void CheckRange(const FrameRange& range, const char* what) {
  LOOPSFM_REQUIRE_OPTION(range.first >= 0 && range.first <= range.last,
                         "{} range {}-{} is not FIRST-LAST with 0 <= FIRST <= LAST", what,
                         range.first, range.last);
}

}  // namespace

void FrameDegradationOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(noise_sigma >= 0.0 && noise_sigma <= 100.0,
                         "noise sigma must be in [0, 100] grey levels, got {}", noise_sigma);
  LOOPSFM_REQUIRE_OPTION(low_texture_contrast >= 0.0 && low_texture_contrast <= 1.0,
                         "low_texture_contrast must be in [0, 1], got {}", low_texture_contrast);
  LOOPSFM_REQUIRE_OPTION(jpeg_quality >= 0 && jpeg_quality <= 100,
                         "jpeg_quality must be 1..100 (or 0 for no JPEG stage), got {}",
                         jpeg_quality);
  for (const FrameRange& range : low_texture) CheckRange(range, "low-texture");
  for (const FrameRange& range : dark) CheckRange(range, "dark");
  for (size_t i = 0; i < motion_blur.size(); ++i) {
    const BlurRange& blur = motion_blur[i];
    CheckRange(blur.frames, "motion blur");
    LOOPSFM_REQUIRE_OPTION(blur.length_pixels >= 1.0 && blur.length_pixels <= kMaxBlurLength,
                           "motion blur length must be between 1 and {} pixels, got {} for "
                           "frames {}-{}",
                           kMaxBlurLength, blur.length_pixels, blur.frames.first,
                           blur.frames.last);
    for (size_t j = 0; j < i; ++j) {
      const FrameRange& a = motion_blur[j].frames;
      LOOPSFM_REQUIRE_OPTION(
          blur.frames.last < a.first || blur.frames.first > a.last,
          "motion blur ranges {}-{} and {}-{} overlap; give every frame one blur length",
          a.first, a.last, blur.frames.first, blur.frames.last);
    }
  }
}

int FrameDegradationOptions::LastFrameNamed() const {
  int last = -1;
  for (const BlurRange& blur : motion_blur) last = std::max(last, blur.frames.last);
  for (const FrameRange& range : low_texture) last = std::max(last, range.last);
  for (const FrameRange& range : dark) last = std::max(last, range.last);
  return last;
}

std::vector<FrameRange> ParseFrameRanges(const std::string& spec) {
  return ParseList<FrameRange>(spec, ParseRange, "frame range",
                               "FIRST-LAST with frame numbers 0 <= FIRST <= LAST (e.g. 200-220), "
                               "several separated by commas");
}

std::vector<BlurRange> ParseBlurRanges(const std::string& spec) {
  auto parse = [](std::string_view text, BlurRange* blur) {
    const size_t colon = text.find(':');
    return colon != std::string_view::npos && ParseRange(text.substr(0, colon), &blur->frames) &&
           ParseNumber(text.substr(colon + 1), &blur->length_pixels) &&
           blur->length_pixels >= 1.0 && blur->length_pixels <= kMaxBlurLength;
  };
  return ParseList<BlurRange>(spec, parse, "blur range",
                              "FIRST-LAST:LENGTH with frame numbers 0 <= FIRST <= LAST and a "
                              "blur length of 1 to 200 pixels (e.g. 120-140:15), several "
                              "separated by commas");
}

void LinearMotionBlur(const Eigen::Vector2d& direction, double length, cv::Mat* image) {
  LOOPSFM_CHECK(length >= 0.0);
  const Eigen::Vector2d unit =
      direction.norm() > 1e-12 ? direction.normalized() : Eigen::Vector2d::UnitX();
  // The segment [-length / 2, length / 2] * unit, sampled every 1/8 pixel and splatted
  // bilinearly onto the kernel grid; symmetric about the centre, so correlation (what
  // filter2D computes) equals convolution.
  const int radius = static_cast<int>(std::ceil(0.5 * length)) + 1;
  cv::Mat kernel = cv::Mat::zeros(2 * radius + 1, 2 * radius + 1, CV_64F);
  const int steps = std::max(2, static_cast<int>(std::ceil(8.0 * length)));
  for (int i = 0; i <= steps; ++i) {
    const Eigen::Vector2d p =
        Eigen::Vector2d::Constant(radius) + (length * i / steps - 0.5 * length) * unit;
    const int x0 = static_cast<int>(std::floor(p.x())), y0 = static_cast<int>(std::floor(p.y()));
    const double fx = p.x() - x0, fy = p.y() - y0;
    kernel.at<double>(y0, x0) += (1.0 - fx) * (1.0 - fy);
    kernel.at<double>(y0, x0 + 1) += fx * (1.0 - fy);
    kernel.at<double>(y0 + 1, x0) += (1.0 - fx) * fy;
    kernel.at<double>(y0 + 1, x0 + 1) += fx * fy;
  }
  kernel /= cv::sum(kernel)[0];
  cv::Mat blurred;
  cv::filter2D(*image, blurred, -1, kernel, cv::Point(-1, -1), 0.0, cv::BORDER_REFLECT);
  *image = blurred;
}

void DegradeFrame(const FrameDegradationOptions& options, int frame,
                  const Eigen::Vector2d& motion, uint64_t seed, cv::Mat* image) {
  LOOPSFM_CHECK(image->type() == CV_8UC3);
  for (const BlurRange& blur : options.motion_blur) {
    if (blur.frames.Contains(frame)) LinearMotionBlur(motion, blur.length_pixels, image);
  }
  if (Covers(options.low_texture, frame)) {
    // Towards the frame's mean grey: out = mean + contrast * (in - mean).
    const cv::Scalar mean = cv::mean(*image);
    const double grey = (mean[0] + mean[1] + mean[2]) / 3.0;
    const double contrast = options.low_texture_contrast;
    image->convertTo(*image, CV_8UC3, contrast, (1.0 - contrast) * grey);
  }
  if (Covers(options.dark, frame)) image->setTo(cv::Scalar::all(0));
  if (options.noise_sigma > 0.0) {
    // One generator per frame, so frames may be degraded in any order.
    cv::RNG rng(Random(Random::SplitMix(seed ^ 0x6e6f697365ull)).Derive(frame).Seed());
    cv::Mat noisy(image->size(), CV_32FC3);
    rng.fill(noisy, cv::RNG::NORMAL, 0.0, options.noise_sigma);
    cv::Mat pixels;
    image->convertTo(pixels, CV_32FC3);
    noisy += pixels;
    noisy.convertTo(*image, CV_8UC3);  // rounds to nearest and clamps to [0, 255]
  }
}

std::vector<uchar> EncodeJpeg(const cv::Mat& image, int quality) {
  LOOPSFM_CHECK(quality >= 1 && quality <= 100);
  std::vector<uchar> bytes;
  LOOPSFM_CHECK(cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, quality}));
  return bytes;
}

cv::Mat JpegRoundTrip(const cv::Mat& image, int quality) {
  return cv::imdecode(EncodeJpeg(image, quality), cv::IMREAD_COLOR);
}

}  // namespace loopsfm
