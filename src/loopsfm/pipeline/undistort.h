#pragma once
// Undistortion to a PINHOLE camera, as the Gaussian-splatting and other pinhole-only tools
// want their input (COLMAP's image_undistorter with its defaults):
//  - the undistorted camera keeps the focal length(s) and gets the largest size whose every
//    pixel comes from inside the distorted image (no blank borders), between min_scale and
//    max_scale of the original size per axis;
//  - images are resampled with OpenCV's undistortion maps (cv::initUndistortRectifyMap, or
//    cv::fisheye's for the fisheye models) and bilinear interpolation;
//  - a model's keypoints move to where the undistorted camera sees their rays, so poses and
//    3D points are unchanged and reprojection errors stay the same.

#include <map>

#include <opencv2/core.hpp>

#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

struct UndistortOptions {
  // Bounds on the undistorted size relative to the distorted one, per axis (COLMAP's).
  double min_scale = 0.2;
  double max_scale = 2.0;
  void Check() const;
};

// The PINHOLE camera that sees what `distorted` sees without distortion (same id).
Camera UndistortedCamera(const Camera& distorted, const UndistortOptions& options = {});

// Resamples images of one camera into its undistorted camera.
class ImageUndistorter {
 public:
  explicit ImageUndistorter(const Camera& distorted, const UndistortOptions& options = {});
  const Camera& undistorted() const { return undistorted_; }
  // Source position (OpenCV pixel coordinates, top-left pixel centre at 0) of each
  // undistorted pixel: CV_32FC1 x and y maps.
  const cv::Mat& map_x() const { return map_x_; }
  const cv::Mat& map_y() const { return map_y_; }
  // Throws InvalidArgument when the image size is not the distorted camera's.
  cv::Mat Undistort(const cv::Mat& image) const;

 private:
  Camera distorted_;
  Camera undistorted_;
  cv::Mat map_x_, map_y_;
};

// The registered images of `model` seen through the undistorted cameras: same poses and 3D
// points, keypoints moved, each camera replaced by undistorted.at(camera_id).
Reconstruction UndistortReconstruction(const Reconstruction& model,
                                       const std::map<camera_t, Camera>& undistorted);

}  // namespace loopsfm
