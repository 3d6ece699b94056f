#pragma once
// Pyramidal Lucas-Kanade tracking of points from one grey frame to the next, with a
// forward-backward check: a point is kept only when tracking it back from where it landed
// returns within max_fb_error_px of where it started. Used by adaptive keyframe selection
// (corners of the last keyframe) and by the localisation of the frames between keyframes
// (keypoints of a keyframe that see a 3D point).

#include <vector>

#include <opencv2/core.hpp>

namespace loopsfm {

struct PointTrackerOptions {
  // Side of the search window at each pyramid level, in pixels.
  int window_px = 21;
  // Pyramid levels above the frame itself.
  int max_level = 3;
  // Forward-backward distance above which a track is dropped, in pixels.
  double max_fb_error_px = 1.0;
};

// Grey 8-bit copy of `image` whose longer side is at most `max_size` (0: no limit); `scale`
// receives the factor from the image's pixels to the copy's.
cv::Mat GreyForTracking(const cv::Mat& image, int max_size, double* scale);

// Tracks `points` from `previous` to `next` (grey frames of one size). On return `tracked`
// holds where each point went and `ok` says which ones were kept (inside the frame, found,
// and passing the forward-backward check).
void TrackPoints(const cv::Mat& previous, const cv::Mat& next,
                 const std::vector<cv::Point2f>& points, const PointTrackerOptions& options,
                 std::vector<cv::Point2f>* tracked, std::vector<unsigned char>* ok);

}  // namespace loopsfm
