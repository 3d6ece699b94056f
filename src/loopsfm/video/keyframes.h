#pragma once
// Keyframe selection, before any feature is extracted.
//
//   windows   one frame in every window of N source frames, by default the sharpest, so
//             motion-blurred frames are skipped (N = 1 keeps every frame);
//   adaptive  a new keyframe only when the view has moved enough since the last one (the
//             thesis' chapter 3.1, as SLAM systems choose keyframes). Corners of the last
//             keyframe are tracked frame to frame with pyramidal Lucas-Kanade on a
//             downscaled grey copy (a forward-backward check drops wrong tracks); a keyframe
//             is due when
//               - the parallax reaches min_parallax_deg: the median angle between a tracked
//                 corner's ray and the keyframe's ray turned by the rotation that best
//                 explains all of them (pure rotation gives no parallax, however far the
//                 camera turns);
//               - or fewer than min_tracked_fraction of the keyframe's corners are still
//                 tracked (the view has moved on: a turn, forward motion);
//               - or tracking breaks (fewer than min_tracked_corners left).
//             The keyframe is then the sharpest frame of the last lookback_seconds; when all
//             of them are blurred (sharpness below blur_fraction of the sharpest frame since
//             the last keyframe, the same view), the next sharp frame within
//             max_defer_seconds is taken instead, else the sharpest seen. When tracking
//             breaks from one frame to the next (a whip pan, a cut), the frame before the
//             break is kept as well, so both sides of it are in the map. Angles and
//             fractions do not depend on the resolution; nothing is counted in frames, so
//             the choice does not depend on the frame rate.

#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "loopsfm/video/frame_source.h"

namespace loopsfm {

// Why a frame was kept. Stored with each frame in the database (storage/database.h).
enum class KeyframeReason : uint8_t {
  kWindow,        // the frame chosen in its fixed window (--every N)
  kFirst,         // adaptive: the first keyframe
  kParallax,      // adaptive: the parallax since the last keyframe reached the threshold
  kOverlap,       // adaptive: too few of the last keyframe's corners still tracked
  kTrackingLost,  // adaptive: tracking broke (blur, a cut, a fast turn)
  kLast,          // adaptive: the end of the video, far enough from the last keyframe
  kFillIn,        // an in-between frame added because two keyframes did not verify
};
std::string_view KeyframeReasonName(KeyframeReason reason);
// The reason named by KeyframeReasonName; nullopt for an unknown name.
std::optional<KeyframeReason> ParseKeyframeReason(std::string_view name);

struct AdaptiveKeyframeOptions {
  // A keyframe once the median parallax since the last one reaches this many degrees.
  double min_parallax_deg = 4.0;
  // ... or once fewer than this fraction of the last keyframe's corners are still tracked.
  double min_tracked_fraction = 0.85;
  // ... or once fewer than this many are (tracking broke).
  int min_tracked_corners = 30;
  // Corners detected in each keyframe.
  int max_corners = 500;
  // Longer side, in pixels, of the grey copies that are tracked (frames smaller than this are
  // tracked as they are).
  int analysis_size = 480;
  // A frame is blurred when its sharpness is below this fraction of the sharpest frame
  // since the last keyframe.
  double blur_fraction = 0.6;
  // Seconds of frames before a due keyframe among which the sharpest is kept.
  double lookback_seconds = 0.2;
  // Seconds after a due keyframe over which a sharp frame is waited for when every frame
  // of the look-back is blurred.
  double max_defer_seconds = 0.5;
  // Focal length of the frames in their own pixels, for the rays (0: 1.2 x the longer
  // side, the guess for an unknown camera). Only the parallax depends on it, weakly.
  double focal_length_px = 0.0;
  void Check() const;
};

// kAuto: adaptive for a video, windows for an image folder (whose images were chosen by
// someone: every one is kept unless --every says otherwise).
enum class KeyframeMode { kAuto, kWindows, kAdaptive };
std::string_view KeyframeModeName(KeyframeMode mode);
// Parses "auto" | "adaptive" | "windows"; throws InvalidArgument naming the choices.
KeyframeMode ParseKeyframeMode(std::string_view name);

struct KeyframeOptions {
  KeyframeMode mode = KeyframeMode::kAuto;
  // Windows: keep one frame in every `every` consecutive source frames (1 keeps all).
  int every = 1;
  // Windows: keep the sharpest frame of each window (largest mean gradient magnitude);
  // otherwise keep the first.
  bool sharpest = true;
  AdaptiveKeyframeOptions adaptive;
  void Check() const;
};

// The mode used for a source of this kind (kAuto resolved).
KeyframeMode ResolvedKeyframeMode(const KeyframeOptions& options, SourceKind kind);

// Twice the smaller of the mean |d/dx| and mean |d/dy| of the grey image: larger is sharper;
// a motion blur along either axis lowers it by what it takes from that axis.
double FrameSharpness(const cv::Mat& image);

struct Keyframe {
  RawFrame frame;
  double sharpness = 0.0;
  KeyframeReason reason = KeyframeReason::kWindow;
};

// What the adaptive selector saw, for the log and the report.
struct KeyframeSummary {
  int frames_read = 0;
  int keyframes = 0;
  // Source indices of the frames judged blurred (kept or not).
  std::vector<int> blurred;
};

class AdaptiveKeyframeSelector;

// Wraps a FrameSource and yields keyframes in source order. Windows hold at most two frames;
// adaptive selection holds the frames of its look-back (a fraction of a second).
class KeyframeSelector {
 public:
  KeyframeSelector(FrameSource& source, const KeyframeOptions& options);
  ~KeyframeSelector();
  std::optional<Keyframe> Next();
  // Adaptive selection only (empty otherwise); complete once Next() has returned nullopt.
  const KeyframeSummary& Summary() const { return summary_; }

 private:
  std::optional<Keyframe> NextInWindow();

  FrameSource& source_;
  KeyframeOptions options_;
  KeyframeSummary summary_;
  std::unique_ptr<AdaptiveKeyframeSelector> adaptive_;
};

}  // namespace loopsfm
