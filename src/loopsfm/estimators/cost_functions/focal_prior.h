#pragma once
// A prior on a camera's focal length, for cameras whose intrinsics are unknown: the
// self-calibrated (or guessed) focal length f0 enters bundle adjustment as a measurement of
// log f with standard deviation sigma_log (0.2: about 20 %).
//
// Why. Along a straight walk past a facade, f and the depths trade off exactly (the images of
// a plane under a translation parallel to it only shift, by f t / Z), so the reprojection
// errors leave f free in that direction and Levenberg-Marquardt can walk it anywhere, even to
// a few pixels (docs/benchmarks.md, "Intrinsics and self-calibration").
// Where the frames constrain f (turns), tens of thousands of reprojection residuals outweigh
// this one term; where they do not, it holds f at the estimate.
//
// Parameter block: the camera's params (size num_params); the focal length is params[0] (for
// models with fx and fy, bundle adjustment ties fy to fx for unknown cameras).

#include <cmath>

#include <ceres/cost_function.h>

namespace loopsfm {

class FocalPriorCost : public ceres::CostFunction {
 public:
  FocalPriorCost(int num_params, double focal_px, double sigma_log)
      : log_focal_(std::log(focal_px)), sigma_log_(sigma_log) {
    set_num_residuals(1);
    mutable_parameter_block_sizes()->push_back(num_params);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double f = parameters[0][0];
    if (!(f > 0.0)) return false;  // the solver rejects the step
    residuals[0] = (std::log(f) - log_focal_) / sigma_log_;
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      const int n = parameter_block_sizes()[0];
      for (int i = 0; i < n; ++i) jacobians[0][i] = 0.0;
      jacobians[0][0] = 1.0 / (f * sigma_log_);
    }
    return true;
  }

 private:
  double log_focal_;
  double sigma_log_;
};

}  // namespace loopsfm
