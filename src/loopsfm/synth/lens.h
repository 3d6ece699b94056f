#pragma once
// The lens of synthetic frames: a COLMAP camera model with its distortion coefficients. The
// renderer unprojects every output pixel through the model to its ray (Camera::CamFromImg), so
// the frames are truly distorted; intrinsics.txt names the model and its parameters.

#include "loopsfm/scene/camera.h"
#include "loopsfm/sensor/camera_models.h"

namespace loopsfm {

struct LensOptions {
  // COLMAP camera model of the rendered frames; PINHOLE renders without distortion.
  CameraModelId model = CameraModelId::kPinhole;
  // Distortion coefficients with OpenCV's names. A model takes those in its parameter list
  // (CameraModelParamNames; the "k" of SIMPLE_RADIAL and SIMPLE_RADIAL_FISHEYE is k1); the
  // others must stay 0.
  double k1 = 0.0;
  double k2 = 0.0;
  double k3 = 0.0;
  double k4 = 0.0;
  double k5 = 0.0;
  double k6 = 0.0;
  double p1 = 0.0;
  double p2 = 0.0;
};

// The camera of synthetic frames of the given size: focal length focal_length_factor * width
// on both axes, the principal point at the image centre, the lens's model and coefficients.
// Throws InvalidArgument when the lens sets a coefficient its model does not take, or when the
// distortion cannot be inverted over the whole image (it folds over inside the image, or an
// image point lies 90 degrees or more from the optical axis).
Camera MakeSynthCamera(const LensOptions& lens, int width, int height,
                       double focal_length_factor);

}  // namespace loopsfm
