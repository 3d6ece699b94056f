#pragma once
// Degradations of rendered frames, as real hand-held footage has them: sensor noise, motion
// blur, washed-out (low-texture) stretches, black frames and JPEG compression. All are
// deterministic: the noise of a frame comes from a generator seeded by the scene's seed and
// the frame number, whatever the thread count.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace loopsfm {

// Frames first..last, both included.
struct FrameRange {
  int first = 0;
  int last = 0;
  bool Contains(int frame) const { return frame >= first && frame <= last; }
};

struct BlurRange {
  FrameRange frames;
  // Length of the linear blur kernel in pixels.
  double length_pixels = 0.0;
};

struct FrameDegradationOptions {
  // Standard deviation of Gaussian sensor noise added to every frame, in grey levels; 0: none.
  double noise_sigma = 0.0;
  // Frame ranges blurred by a line kernel along the image motion (from the true poses).
  std::vector<BlurRange> motion_blur;
  // Frame ranges washed out towards flat grey (fog, over-exposure), so few features survive.
  std::vector<FrameRange> low_texture;
  // Contrast left in low-texture frames, around the frame's mean grey (1 keeps the frame);
  // 0.25 leaves ~2% of the SIFT features (contrast threshold 0.02) of a street frame.
  double low_texture_contrast = 0.25;
  // Frame ranges that are black (lens covered) before the sensor noise is added.
  std::vector<FrameRange> dark;
  // JPEG quality 1..100: images are written as .jpg, video frames go through JPEG before the
  // H.264 encoder (whose quality OpenCV does not expose); 0: no JPEG stage.
  int jpeg_quality = 0;

  // Throws InvalidArgument naming the offending field or range.
  void Check() const;
  // The last frame any range names, or -1 when there are none.
  int LastFrameNamed() const;
};

// Parses "FIRST-LAST[,FIRST-LAST...]" (inclusive frame numbers; "FIRST" alone is one frame).
// Throws InvalidArgument naming the bad part and what to write instead.
std::vector<FrameRange> ParseFrameRanges(const std::string& spec);

// Parses "FIRST-LAST:LENGTH[,FIRST-LAST:LENGTH...]" (LENGTH in pixels, may have decimals).
std::vector<BlurRange> ParseBlurRanges(const std::string& spec);

// Applies to `image` (8-bit BGR) the degradations of `options` that cover `frame`, in the
// order a camera would: motion blur along `motion` (image motion, pixels per frame; any
// length), low texture, darkness, sensor noise. The JPEG stage is left to the writer.
void DegradeFrame(const FrameDegradationOptions& options, int frame,
                  const Eigen::Vector2d& motion, uint64_t seed, cv::Mat* image);

// Blurs `image` with a line of `length` pixels centred on each pixel, along `direction`
// (horizontal where it is zero); borders are reflected.
void LinearMotionBlur(const Eigen::Vector2d& direction, double length, cv::Mat* image);

// The frame as a reader decodes it after JPEG compression at `quality`.
cv::Mat JpegRoundTrip(const cv::Mat& image, int quality);

// `image` compressed as JPEG at `quality`.
std::vector<uchar> EncodeJpeg(const cv::Mat& image, int quality);

}  // namespace loopsfm
