#include "loopsfm/video/point_tracker.h"

#include <algorithm>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace loopsfm {

cv::Mat GreyForTracking(const cv::Mat& image, int max_size, double* scale) {
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = image.clone();
  }
  const int longer = std::max(grey.cols, grey.rows);
  *scale = 1.0;
  if (max_size > 0 && longer > max_size) {
    *scale = static_cast<double>(max_size) / longer;
    cv::Mat small;
    cv::resize(grey, small, cv::Size(), *scale, *scale, cv::INTER_AREA);
    return small;
  }
  return grey;
}

void TrackPoints(const cv::Mat& previous, const cv::Mat& next,
                 const std::vector<cv::Point2f>& points, const PointTrackerOptions& options,
                 std::vector<cv::Point2f>* tracked, std::vector<unsigned char>* ok) {
  tracked->clear();
  ok->assign(points.size(), 0);
  if (points.empty()) return;
  const cv::Size window(options.window_px, options.window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
  std::vector<unsigned char> forward_ok, backward_ok;
  std::vector<float> errors;
  cv::calcOpticalFlowPyrLK(previous, next, points, *tracked, forward_ok, errors, window,
                           options.max_level, criteria);
  std::vector<cv::Point2f> back;
  cv::calcOpticalFlowPyrLK(next, previous, *tracked, back, backward_ok, errors, window,
                           options.max_level, criteria);
  const double max_fb2 = options.max_fb_error_px * options.max_fb_error_px;
  for (size_t i = 0; i < points.size(); ++i) {
    const cv::Point2f& p = (*tracked)[i];
    const bool inside =
        p.x >= 0.f && p.y >= 0.f && p.x <= next.cols - 1.f && p.y <= next.rows - 1.f;
    const cv::Point2f d = back[i] - points[i];
    (*ok)[i] = forward_ok[i] && backward_ok[i] && inside && d.dot(d) <= max_fb2;
  }
}

}  // namespace loopsfm
