#include "loopsfm/pipeline/undistort.h"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// A camera as OpenCV's undistortion takes it (Camera::ToOpenCv, K in OpenCV's pixels).
struct OpenCvLens {
  cv::Matx33d K;
  std::vector<double> distortion;  // (k1, k2, p1, p2, k3, k4, k5, k6) or fisheye (k1..k4)
  bool fisheye = false;
};

// OpenCV's K: its top-left pixel centre is at 0, COLMAP's at 0.5.
OpenCvLens ToOpenCv(const Camera& camera) {
  const OpenCvIntrinsics o = camera.ToOpenCv();
  return {cv::Matx33d(o.fx, 0.0, o.cx - 0.5, 0.0, o.fy, o.cy - 0.5, 0.0, 0.0, 1.0), o.distortion,
          o.fisheye};
}

}  // namespace

void UndistortOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_scale > 0.0 && min_scale <= 1.0 && max_scale >= 1.0,
                         "undistortion scale bounds must hold 1 (got {} .. {})", min_scale,
                         max_scale);
}

Camera UndistortedCamera(const Camera& distorted, const UndistortOptions& options) {
  options.Check();
  const OpenCvIntrinsics lens = distorted.ToOpenCv();
  const double fx = lens.fx, fy = lens.fy;
  // The undistorted rays of the image border, on the normalised plane: the largest
  // rectangle inside them holds only pixels that come from the image.
  const int steps = 100;
  double left = -1e300, right = 1e300, top = -1e300, bottom = 1e300;
  // Through the centres of the outermost pixels, so that interpolation never reaches outside.
  const double w = distorted.width, h = distorted.height;
  for (int i = 0; i <= steps; ++i) {
    const double x = 0.5 + (w - 1.0) * i / steps, y = 0.5 + (h - 1.0) * i / steps;
    left = std::max(left, distorted.CamFromImg({0.5, y}).x());
    right = std::min(right, distorted.CamFromImg({w - 0.5, y}).x());
    top = std::max(top, distorted.CamFromImg({x, 0.5}).y());
    bottom = std::min(bottom, distorted.CamFromImg({x, h - 0.5}).y());
  }
  // Pixel centres one pixel apart span the rectangle: one pixel more than its extent. Sizes
  // within the scale bounds, the rectangle shrunk or grown about its centre.
  const double width =
      std::clamp(fx * (right - left) + 1.0 + 1e-6, options.min_scale * w, options.max_scale * w);
  const double height =
      std::clamp(fy * (bottom - top) + 1.0 + 1e-6, options.min_scale * h, options.max_scale * h);
  const double centre_x = 0.5 * (left + right), centre_y = 0.5 * (top + bottom);
  Camera undistorted;
  undistorted.camera_id = distorted.camera_id;
  undistorted.model_id = CameraModelId::kPinhole;
  undistorted.width = std::max(1, static_cast<int>(std::floor(width)));
  undistorted.height = std::max(1, static_cast<int>(std::floor(height)));
  undistorted.params = {fx, fy, 0.5 * undistorted.width - fx * centre_x,
                        0.5 * undistorted.height - fy * centre_y};
  undistorted.has_prior_focal_length = distorted.has_prior_focal_length;
  return undistorted;
}

ImageUndistorter::ImageUndistorter(const Camera& distorted, const UndistortOptions& options)
    : distorted_(distorted), undistorted_(UndistortedCamera(distorted, options)) {
  const OpenCvLens lens = ToOpenCv(distorted);
  const cv::Matx33d new_k = ToOpenCv(undistorted_).K;
  const cv::Size size(undistorted_.width, undistorted_.height);
  if (lens.fisheye) {
    cv::fisheye::initUndistortRectifyMap(lens.K, lens.distortion, cv::Matx33d::eye(), new_k, size,
                                         CV_32FC1, map_x_, map_y_);
  } else {
    cv::initUndistortRectifyMap(lens.K, lens.distortion, cv::Matx33d::eye(), new_k, size,
                                CV_32FC1, map_x_, map_y_);
  }
}

cv::Mat ImageUndistorter::Undistort(const cv::Mat& image) const {
  if (image.cols != distorted_.width || image.rows != distorted_.height) {
    throw InvalidArgument(fmt::format("a {}x{} frame cannot be undistorted with camera {} ({}x{})",
                                      image.cols, image.rows, distorted_.camera_id,
                                      distorted_.width, distorted_.height));
  }
  cv::Mat out;
  cv::remap(image, out, map_x_, map_y_, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  return out;
}

Reconstruction UndistortReconstruction(const Reconstruction& model,
                                       const std::map<camera_t, Camera>& undistorted) {
  Reconstruction out = model;
  for (const auto& [id, image] : model.Images()) {
    const Camera& from = model.GetCamera(image.camera_id);
    const Camera& to = undistorted.at(image.camera_id);
    for (Point2D& point : out.GetImage(id).points2D) {
      point.xy = to.ImgFromCam(from.CamFromImg(point.xy).homogeneous());
    }
  }
  for (const auto& [id, camera] : undistorted) out.GetCamera(id) = camera;
  return out;
}

}  // namespace loopsfm
