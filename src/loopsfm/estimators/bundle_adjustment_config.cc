// The bundle adjuster's options and configuration (bundle_adjustment.h), and the gauge
// helpers built on them; the adjuster itself is in bundle_adjustment.cc.
#include "loopsfm/estimators/bundle_adjustment.h"

#include <algorithm>

#include "loopsfm/util/errors.h"

namespace loopsfm {

BundleAdjustmentOptions BundleAdjustmentOptions::Local() {
  BundleAdjustmentOptions options;
  options.max_num_iterations = 25;
  // A video's tracks lengthen each time the walk passes a place again; without a cap, each
  // registration's bundle would grow with them.
  options.max_constant_observations_per_point = 4;
  // The new frame's neighbours have settled long before the new points stop creeping.
  options.settle_tolerance = 1e-5;
  return options;
}

BundleAdjustmentOptions BundleAdjustmentOptions::Global() {
  BundleAdjustmentOptions options;
  options.max_num_iterations = 100;
  // Soft L1 from 0.7 px instead of 1 px (SIFT's keypoints are good to about half a pixel):
  // observations a pixel or two off weigh less in the model every output comes from
  // (docs/mapper_options.md).
  options.loss_function_scale = 0.7;
  options.settle_tolerance = 1e-5;
  // loopsfm's models are sequences: a frame shares points with the frames near it on the
  // path (and, after a loop, near the places it returns to), so the reduced camera system
  // stays sparse past COLMAP's 1,000 images, the bound chosen for unordered photo
  // collections, and sparse Schur takes fewer and cheaper iterations than iterative Schur,
  // whose conjugate gradients converge slowly on a long chain of frames. Its factor grows
  // faster than the problem and costs memory; this bound keeps it to the sizes measured
  // (docs/scale).
  options.sparse_schur_max_num_images = 4000;
  return options;
}

void BundleAdjustmentOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(loss_function_scale > 0.0,
                         "bundle adjustment: loss_function_scale must be > 0 (got {})",
                         loss_function_scale);
  LOOPSFM_REQUIRE_OPTION(max_constant_observations_per_point >= 0,
                         "bundle adjustment: max_constant_observations_per_point must be >= 0 (got {})",
                         max_constant_observations_per_point);
  LOOPSFM_REQUIRE_OPTION(max_num_iterations >= 0,
                         "bundle adjustment: max_num_iterations must be >= 0 (got {})",
                         max_num_iterations);
  LOOPSFM_REQUIRE_OPTION(
      function_tolerance >= 0.0 && gradient_tolerance >= 0.0 && parameter_tolerance >= 0.0,
      "bundle adjustment: tolerances must be >= 0");
  LOOPSFM_REQUIRE_OPTION(settle_tolerance >= 0.0,
                         "bundle adjustment: settle_tolerance must be >= 0 (got {})",
                         settle_tolerance);
  LOOPSFM_REQUIRE_OPTION(max_linear_solver_iterations >= 1,
                         "bundle adjustment: max_linear_solver_iterations must be >= 1 (got {})",
                         max_linear_solver_iterations);
  LOOPSFM_REQUIRE_OPTION(
      dense_schur_max_num_images >= 0 && sparse_schur_max_num_images >= dense_schur_max_num_images,
      "bundle adjustment: need 0 <= dense_schur_max_num_images <= sparse_schur_max_num_images "
      "(got {} and {})",
      dense_schur_max_num_images, sparse_schur_max_num_images);
}

void BundleAdjustmentConfig::RemoveImage(image_t image_id) {
  image_ids_.erase(image_id);
  constant_poses_.erase(image_id);
  constant_centre_.erase(image_id);
}

void BundleAdjustmentConfig::SetConstantCentreCoords(image_t image_id, std::vector<int> coords) {
  std::sort(coords.begin(), coords.end());
  coords.erase(std::unique(coords.begin(), coords.end()), coords.end());
  for (const int c : coords) LOOPSFM_CHECK_MSG(c >= 0 && c < 3, "centre coord {}", c);
  constant_centre_[image_id] = std::move(coords);
}

const std::vector<int>* BundleAdjustmentConfig::ConstantCentreCoords(image_t image_id) const {
  const auto it = constant_centre_.find(image_id);
  return it == constant_centre_.end() ? nullptr : &it->second;
}

void BundleAdjustmentConfig::AddVariablePoint(point3D_t point3D_id) {
  constant_points_.erase(point3D_id);
  variable_points_.insert(point3D_id);
}

void BundleAdjustmentConfig::AddConstantPoint(point3D_t point3D_id) {
  variable_points_.erase(point3D_id);
  constant_points_.insert(point3D_id);
}

void FixGaugeWithTwoImages(const Reconstruction& reconstruction, image_t first_image_id,
                           image_t second_image_id, BundleAdjustmentConfig* config) {
  LOOPSFM_CHECK(first_image_id != second_image_id);
  const Image& first = reconstruction.GetImage(first_image_id);
  const Image& second = reconstruction.GetImage(second_image_id);
  // With the first pose fixed, the remaining gauge freedom is a scaling about the first
  // centre C1, which moves the second centre along the baseline C2 - C1.
  const Eigen::Vector3d baseline = second.ProjectionCenter() - first.ProjectionCenter();
  int coord = 0;
  baseline.cwiseAbs().maxCoeff(&coord);
  config->SetConstantPose(first_image_id);
  config->SetConstantCentreCoords(second_image_id, {coord});
}

image_t FarthestRegisteredImage(const Reconstruction& reconstruction, image_t from,
                                image_t fallback) {
  const Eigen::Vector3d first = reconstruction.GetImage(from).ProjectionCenter();
  image_t farthest = fallback;
  double largest = (reconstruction.GetImage(fallback).ProjectionCenter() - first).squaredNorm();
  for (const image_t id : reconstruction.RegImageIds()) {
    const double distance = (reconstruction.GetImage(id).ProjectionCenter() - first).squaredNorm();
    if (distance > largest || (distance == largest && id < farthest)) {
      largest = distance;
      farthest = id;
    }
  }
  return farthest;
}

}  // namespace loopsfm
