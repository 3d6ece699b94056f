#pragma once
// A camera: intrinsic model and parameters, shared by all frames taken with it.

#include <string>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/sensor/camera_models.h"
#include "loopsfm/util/types.h"

namespace loopsfm {

// A camera in OpenCV's form, which calib3d's undistortion, nerfstudio and most other tools
// take: focal lengths and principal point (COLMAP's pixel convention: the top-left pixel's
// centre at 0.5), and the distortion in OpenCV's order, (k1, k2, p1, p2, k3, k4, k5, k6)
// for the perspective models and (k1, k2, k3, k4) for the fisheye ones, zero where the
// model has no such term.
struct OpenCvIntrinsics {
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
  std::vector<double> distortion;
  bool fisheye = false;
};

struct Camera {
  camera_t camera_id = kInvalidCameraId;
  CameraModelId model_id = CameraModelId::kPinhole;
  int width = 0;
  int height = 0;
  // In the model's order (see kParamsInfo), COLMAP's pixel convention.
  std::vector<double> params;
  // True when the focal length came from the user or calibration, not from a guess.
  bool has_prior_focal_length = false;

  // A camera of the given model for unknown intrinsics: focal length(s) 1.2 * max(width,
  // height) (COLMAP's guess for images without EXIF; self-calibration replaces it before
  // mapping), the principal point at the image centre, no distortion.
  static Camera GuessFromImageSize(int width, int height,
                                   CameraModelId model_id = CameraModelId::kSimpleRadial);
  // Sets every focal length parameter (one, or fx and fy) to focal_px.
  void SetFocalLength(double focal_px);

  std::string ModelName() const { return std::string(CameraModelName(model_id)); }
  double MeanFocalLength() const;
  OpenCvIntrinsics ToOpenCv() const;
  // Normalised image-plane coordinates (z = 1) of a pixel.
  Eigen::Vector2d CamFromImg(const Eigen::Vector2d& pixel) const;
  // Pixel of a point in camera coordinates (z > 0 expected).
  Eigen::Vector2d ImgFromCam(const Eigen::Vector3d& point_in_cam) const;
  // Converts a pixel threshold to a threshold on normalised coordinates.
  double CamFromImgThreshold(double pixels) const { return pixels / MeanFocalLength(); }
  // Throws InputError when the parameter count does not fit the model or sizes are invalid.
  void Check() const;
  bool SameIntrinsics(const Camera& other) const {
    return model_id == other.model_id && width == other.width && height == other.height &&
           params == other.params;
  }
};

}  // namespace loopsfm
