#pragma once
// Ends a bundle adjustment once its cameras have settled (BundleAdjustmentOptions::
// settle_tolerance): two successful steps in a row that moved no camera centre by more than
// the tolerance times the centres' spread, turned no camera by more than the tolerance in
// radians and changed no camera parameter by more than the tolerance times max(|value|, 1).
// Reads the poses and parameters from the reconstruction after each step, so the solver
// needs update_state_every_iteration.
#include <vector>

#include <ceres/ceres.h>

#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

// RMS distance of the centres from their mean (0 for none): the length unit of the settle
// test and of the bundle's centre priors.
double CentreSpread(const std::vector<Eigen::Vector3d>& centres);

class SettledCallback : public ceres::IterationCallback {
 public:
  // image_ids: the variable poses; camera_ids: the cameras with refined parameters.
  SettledCallback(const Reconstruction& reconstruction, std::vector<image_t> image_ids,
                  std::vector<camera_t> camera_ids, double tolerance);
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override;

 private:
  void Snapshot();

  const Reconstruction& reconstruction_;
  const std::vector<image_t> image_ids_;
  const std::vector<camera_t> camera_ids_;
  const double tolerance_;
  double spread_ = 0.0;
  int num_settled_ = 0;
  std::vector<Eigen::Vector3d> centres_;
  std::vector<Eigen::Quaterniond> rotations_;
  std::vector<double> params_;
};

}  // namespace loopsfm
