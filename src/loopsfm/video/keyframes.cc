#include "loopsfm/video/keyframes.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/video/point_tracker.h"

namespace loopsfm {

namespace {

constexpr std::array<std::pair<KeyframeReason, std::string_view>, 7> kReasonNames = {{
    {KeyframeReason::kWindow, "window"},
    {KeyframeReason::kFirst, "first"},
    {KeyframeReason::kParallax, "parallax"},
    {KeyframeReason::kOverlap, "overlap"},
    {KeyframeReason::kTrackingLost, "tracking-lost"},
    {KeyframeReason::kLast, "last"},
    {KeyframeReason::kFillIn, "fill-in"},
}};

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

}  // namespace

std::string_view KeyframeReasonName(KeyframeReason reason) {
  for (const auto& [r, name] : kReasonNames) {
    if (r == reason) return name;
  }
  return "unknown";
}

std::optional<KeyframeReason> ParseKeyframeReason(std::string_view name) {
  for (const auto& [r, n] : kReasonNames) {
    if (n == name) return r;
  }
  return std::nullopt;
}

std::string_view KeyframeModeName(KeyframeMode mode) {
  switch (mode) {
    case KeyframeMode::kAuto: return "auto";
    case KeyframeMode::kWindows: return "windows";
    case KeyframeMode::kAdaptive: return "adaptive";
  }
  return "auto";
}

KeyframeMode ParseKeyframeMode(std::string_view name) {
  for (const KeyframeMode mode :
       {KeyframeMode::kAuto, KeyframeMode::kWindows, KeyframeMode::kAdaptive}) {
    if (KeyframeModeName(mode) == name) return mode;
  }
  throw InvalidArgument(fmt::format(
      "unknown keyframe mode '{}': choose auto (adaptive for a video, every image of a folder), "
      "adaptive or windows (one frame in every --every N)", name));
}

KeyframeMode ResolvedKeyframeMode(const KeyframeOptions& options, SourceKind kind) {
  if (options.mode != KeyframeMode::kAuto) return options.mode;
  return kind == SourceKind::kVideo ? KeyframeMode::kAdaptive : KeyframeMode::kWindows;
}

void AdaptiveKeyframeOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_parallax_deg > 0.0 && min_parallax_deg < 90.0,
                         "--keyframe-parallax must be in (0, 90) degrees, got {}",
                         min_parallax_deg);
  LOOPSFM_REQUIRE_OPTION(min_tracked_fraction > 0.0 && min_tracked_fraction < 1.0,
                         "--keyframe-overlap must be in (0, 1), got {}", min_tracked_fraction);
  LOOPSFM_REQUIRE_OPTION(min_tracked_corners >= 8 && max_corners > min_tracked_corners,
                         "keyframes: need 8 <= min_tracked_corners < max_corners, got {} and {}",
                         min_tracked_corners, max_corners);
  LOOPSFM_REQUIRE_OPTION(analysis_size >= 64,
                         "keyframes: analysis_size must be at least 64, got {}", analysis_size);
  LOOPSFM_REQUIRE_OPTION(blur_fraction >= 0.0 && blur_fraction < 1.0,
                         "keyframes: blur_fraction must be in [0, 1), got {}", blur_fraction);
  LOOPSFM_REQUIRE_OPTION(lookback_seconds >= 0.0 && max_defer_seconds >= 0.0,
                         "keyframes: look-back and deferral must not be negative");
  LOOPSFM_REQUIRE_OPTION(focal_length_px >= 0.0, "keyframes: focal length must not be negative");
}

void KeyframeOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(every >= 1, "--every must be at least 1, got {}", every);
  if (mode != KeyframeMode::kWindows) adaptive.Check();
  LOOPSFM_REQUIRE_OPTION(every == 1 || mode == KeyframeMode::kWindows,
                         "--every {} keeps fixed windows: it cannot be combined with --keyframes "
                         "{}; drop one of them",
                         every, KeyframeModeName(mode));
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
  // Motion blur smears along one direction and leaves the other: the weaker direction tells
  // it (a frame blurred sideways keeps its vertical gradients, half of the sum).
  const double x = cv::sum(cv::abs(dx))[0], y = cv::sum(cv::abs(dy))[0];
  return 2.0 * std::min(x, y) / static_cast<double>(grey.total());
}

// The adaptive rule of keyframes.h, one source frame at a time.
class AdaptiveKeyframeSelector {
 public:
  AdaptiveKeyframeSelector(FrameSource& source, const AdaptiveKeyframeOptions& options,
                           KeyframeSummary* summary)
      : source_(source), options_(options), summary_(*summary) {
    const double fps = source.Info().fps > 0.0 ? source.Info().fps : 30.0;
    lookback_frames_ = std::max<size_t>(1, std::lround(options.lookback_seconds * fps));
    defer_frames_ = static_cast<size_t>(std::lround(options.max_defer_seconds * fps));
  }

  std::optional<Keyframe> Next() {
    while (pending_.empty() && !ended_) {
      std::optional<RawFrame> frame = source_.Next();
      if (frame) {
        Process(std::move(*frame));
      } else {
        ended_ = true;
        Finish();
      }
    }
    if (pending_.empty()) return std::nullopt;
    Keyframe keyframe = std::move(pending_.front());
    pending_.pop_front();
    return keyframe;
  }

 private:
  struct Seen {
    RawFrame frame;
    double sharpness = 0.0;
    bool blurred = false;
    cv::Mat grey;  // downscaled, for tracking
  };

  void Process(RawFrame frame) {
    ++summary_.frames_read;
    Seen seen;
    seen.sharpness = FrameSharpness(frame.image);
    seen.grey = GreyForTracking(frame.image, options_.analysis_size, &scale_);
    seen.frame = std::move(frame);
    // Blur is judged within one view: against the frames tracked since the last keyframe
    // (a new view may hold less texture without being blurred).
    view_sharpest_ = std::max(view_sharpest_, seen.sharpness);
    seen.blurred = seen.sharpness < options_.blur_fraction * view_sharpest_;
    if (seen.blurred) summary_.blurred.push_back(seen.frame.source_index);

    if (!have_keyframe_) {
      recent_.push_back(std::move(seen));
      if (recent_.size() >= lookback_frames_) EmitBest(KeyframeReason::kFirst);
      return;
    }
    Track(seen.grey);
    recent_.push_back(std::move(seen));
    if (deferred_) {
      // Waiting for a sharp frame after a due keyframe whose look-back was all blurred.
      if (!recent_.back().blurred) {
        Emit(recent_.size() - 1, *deferred_);
      } else if (++deferred_for_ >= defer_frames_) {
        EmitBest(*deferred_);
      }
      return;
    }
    if (recent_.size() > lookback_frames_) recent_.pop_front();
    const std::optional<KeyframeReason> due = Due();
    if (!due) return;
    if (*due == KeyframeReason::kTrackingLost && recent_.size() >= 2 &&
        !recent_[recent_.size() - 2].blurred) {
      // The view broke between the last two frames (a whip pan, a cut): the frame before the
      // break is kept too, so both sides of it are in the map.
      Emit(recent_.size() - 2, KeyframeReason::kTrackingLost);
    }
    if (BestCandidate().blurred && defer_frames_ > 0) {
      deferred_ = due;
      deferred_for_ = 0;
      return;
    }
    EmitBest(*due);
  }

  // At the end: the last frames become a keyframe when they are half a keyframe step away.
  void Finish() {
    if (!have_keyframe_ && !recent_.empty()) EmitBest(KeyframeReason::kFirst);
    if (recent_.empty()) return;
    const bool far_enough =
        deferred_ || tracked_.size() < static_cast<size_t>(options_.min_tracked_corners) ||
        parallax_deg_ >= 0.5 * options_.min_parallax_deg ||
        Fraction() < 0.5 * (1.0 + options_.min_tracked_fraction);
    if (far_enough) EmitBest(KeyframeReason::kLast);
  }

  double Fraction() const {
    return num_corners_ > 0 ? static_cast<double>(tracked_.size()) / num_corners_ : 0.0;
  }

  std::optional<KeyframeReason> Due() const {
    if (num_corners_ < options_.min_tracked_corners) {
      // The keyframe had too little texture to track: the next frame that has enough.
      return CountCorners(recent_.back().grey) >= options_.min_tracked_corners
                 ? std::optional(KeyframeReason::kTrackingLost)
                 : std::nullopt;
    }
    if (tracked_.size() < static_cast<size_t>(options_.min_tracked_corners)) {
      return KeyframeReason::kTrackingLost;
    }
    if (Fraction() < options_.min_tracked_fraction) return KeyframeReason::kOverlap;
    if (parallax_deg_ >= options_.min_parallax_deg) return KeyframeReason::kParallax;
    return std::nullopt;
  }

  // The sharpest frame of the look-back, preferring the latest of those within 10 % of it
  // (the most parallax); for the first keyframe, the earliest that is not blurred (the video
  // starts there).
  size_t BestIndex(bool first = false) const {
    double sharpest = 0.0;
    for (const Seen& s : recent_) sharpest = std::max(sharpest, s.sharpness);
    const double good_enough = first ? options_.blur_fraction * sharpest : 0.9 * sharpest;
    for (size_t k = 0; k < recent_.size(); ++k) {
      const size_t i = first ? k : recent_.size() - 1 - k;
      if (recent_[i].sharpness >= good_enough) return i;
    }
    return recent_.size() - 1;
  }
  const Seen& BestCandidate() const { return recent_[BestIndex()]; }

  void EmitBest(KeyframeReason reason) {
    Emit(BestIndex(reason == KeyframeReason::kFirst), reason);
  }

  // Keeps recent_[index] and starts tracking from it again, through the frames after it.
  void Emit(size_t index, KeyframeReason reason) {
    Seen& chosen = recent_[index];
    spdlog::debug("keyframe {} ({}): parallax {:.2f} deg, {} of {} corners tracked at frame {}",
                  chosen.frame.source_index, KeyframeReasonName(reason), parallax_deg_,
                  tracked_.size(), num_corners_, recent_.back().frame.source_index);
    pending_.push_back(Keyframe{std::move(chosen.frame), chosen.sharpness, reason});
    ++summary_.keyframes;
    have_keyframe_ = true;
    deferred_.reset();
    StartTracking(chosen.grey);
    view_sharpest_ = chosen.sharpness;
    for (size_t j = index + 1; j < recent_.size(); ++j) {
      Track(recent_[j].grey);
      view_sharpest_ = std::max(view_sharpest_, recent_[j].sharpness);
    }
    recent_.erase(recent_.begin(), recent_.begin() + static_cast<std::ptrdiff_t>(index) + 1);
  }

  std::vector<cv::Point2f> DetectCorners(const cv::Mat& grey) const {
    std::vector<cv::Point2f> corners;
    const double min_distance = std::max(grey.cols, grey.rows) / 50.0;
    cv::goodFeaturesToTrack(grey, corners, options_.max_corners, 0.01, min_distance);
    return corners;
  }
  int CountCorners(const cv::Mat& grey) const {
    return static_cast<int>(DetectCorners(grey).size());
  }

  void StartTracking(const cv::Mat& grey) {
    keyframe_corners_ = DetectCorners(grey);
    num_corners_ = static_cast<int>(keyframe_corners_.size());
    tracked_.clear();
    positions_ = keyframe_corners_;
    for (int i = 0; i < num_corners_; ++i) tracked_.push_back(i);
    previous_grey_ = grey;
    parallax_deg_ = 0.0;
    const double focal = options_.focal_length_px > 0.0
                             ? options_.focal_length_px * scale_
                             : 1.2 * std::max(grey.cols, grey.rows);
    focal_ = focal;
    centre_ = cv::Point2f(0.5f * grey.cols, 0.5f * grey.rows);
  }

  void Track(const cv::Mat& grey) {
    if (!tracked_.empty()) {
      std::vector<cv::Point2f> next;
      std::vector<unsigned char> ok;
      TrackPoints(previous_grey_, grey, positions_, tracker_, &next, &ok);
      std::vector<int> kept_ids;
      std::vector<cv::Point2f> kept_positions;
      for (size_t i = 0; i < ok.size(); ++i) {
        if (!ok[i]) continue;
        kept_ids.push_back(tracked_[i]);
        kept_positions.push_back(next[i]);
      }
      tracked_ = std::move(kept_ids);
      positions_ = std::move(kept_positions);
    }
    previous_grey_ = grey;
    parallax_deg_ = Parallax();
  }

  Eigen::Vector3d Ray(const cv::Point2f& p) const {
    return Eigen::Vector3d((p.x - centre_.x) / focal_, (p.y - centre_.y) / focal_, 1.0)
        .normalized();
  }

  // Median angle (degrees) between the tracked corners' rays and the keyframe's rays turned
  // by the best rotation (Kabsch), fitted again on the corners within 3x the median.
  double Parallax() const {
    const size_t n = tracked_.size();
    if (n < 3) return 0.0;
    std::vector<Eigen::Vector3d> from(n), to(n);
    for (size_t i = 0; i < n; ++i) {
      from[i] = Ray(keyframe_corners_[tracked_[i]]);
      to[i] = Ray(positions_[i]);
    }
    std::vector<char> use(n, 1);
    std::vector<double> angles(n);
    for (int round = 0; round < 2; ++round) {
      Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
      for (size_t i = 0; i < n; ++i) {
        if (use[i]) h += from[i] * to[i].transpose();
      }
      const Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
      d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
      const Eigen::Matrix3d rotation = svd.matrixV() * d * svd.matrixU().transpose();
      for (size_t i = 0; i < n; ++i) {
        angles[i] = std::acos(std::clamp(to[i].dot(rotation * from[i]), -1.0, 1.0));
      }
      const double median = Median(angles);
      for (size_t i = 0; i < n; ++i) use[i] = angles[i] <= 3.0 * median + 1e-9;
    }
    return Median(angles) * 180.0 / M_PI;
  }

  FrameSource& source_;
  AdaptiveKeyframeOptions options_;
  KeyframeSummary& summary_;
  PointTrackerOptions tracker_;
  size_t lookback_frames_ = 1, defer_frames_ = 0;
  bool ended_ = false;
  bool have_keyframe_ = false;
  std::deque<Keyframe> pending_;
  // Frames since the last keyframe (at most the look-back, more while deferring).
  std::deque<Seen> recent_;
  // The sharpest frame since the last keyframe (the keyframe included).
  double view_sharpest_ = 0.0;
  std::optional<KeyframeReason> deferred_;
  size_t deferred_for_ = 0;
  // Tracking state: the keyframe's corners, which of them are still tracked and where.
  double scale_ = 1.0, focal_ = 1.0;
  cv::Point2f centre_;
  std::vector<cv::Point2f> keyframe_corners_;
  int num_corners_ = 0;
  std::vector<int> tracked_;
  std::vector<cv::Point2f> positions_;
  cv::Mat previous_grey_;
  double parallax_deg_ = 0.0;
};

KeyframeSelector::KeyframeSelector(FrameSource& source, const KeyframeOptions& options)
    : source_(source), options_(options) {
  options_.Check();
  if (ResolvedKeyframeMode(options_, source.Info().kind) == KeyframeMode::kAdaptive) {
    adaptive_ = std::make_unique<AdaptiveKeyframeSelector>(source_, options_.adaptive, &summary_);
  }
}

KeyframeSelector::~KeyframeSelector() = default;

std::optional<Keyframe> KeyframeSelector::Next() {
  return adaptive_ ? adaptive_->Next() : NextInWindow();
}

std::optional<Keyframe> KeyframeSelector::NextInWindow() {
  if (options_.every == 1 || !options_.sharpest) {
    std::optional<RawFrame> frame = source_.Next();
    if (!frame) return std::nullopt;
    for (int i = 1; i < options_.every && source_.Skip(); ++i) {
    }
    Keyframe keyframe{std::move(*frame), 0.0, KeyframeReason::kWindow};
    keyframe.sharpness = FrameSharpness(keyframe.frame.image);
    return keyframe;
  }
  std::optional<Keyframe> best;
  for (int i = 0; i < options_.every; ++i) {
    std::optional<RawFrame> frame = source_.Next();
    if (!frame) break;
    const double sharpness = FrameSharpness(frame->image);
    if (!best || sharpness > best->sharpness) {
      best = Keyframe{std::move(*frame), sharpness, KeyframeReason::kWindow};
    }
  }
  return best;
}

}  // namespace loopsfm
