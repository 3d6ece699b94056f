#pragma once
// Keyframe selection: keep one frame in every window of N, by default the sharpest one,
// so motion-blurred frames are skipped.

#include <memory>
#include <optional>

#include "loopsfm/video/frame_source.h"

namespace loopsfm {

struct KeyframeOptions {
  // Keep one frame in every `every` consecutive source frames (1 keeps all).
  int every = 1;
  // Keep the sharpest frame of each window (largest mean gradient magnitude); otherwise
  // keep the first.
  bool sharpest = true;
  void Check() const;
};

// Mean gradient magnitude (|d/dx| + |d/dy| of the grey image): larger is sharper.
double FrameSharpness(const cv::Mat& image);

struct Keyframe {
  RawFrame frame;
  double sharpness = 0.0;
};

// Wraps a FrameSource and yields one keyframe per window. Holds at most two frames.
class KeyframeSelector {
 public:
  KeyframeSelector(FrameSource& source, const KeyframeOptions& options);
  std::optional<Keyframe> Next();

 private:
  FrameSource& source_;
  KeyframeOptions options_;
};

}  // namespace loopsfm
