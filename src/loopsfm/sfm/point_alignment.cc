#include "loopsfm/sfm/point_alignment.h"

#include <algorithm>
#include <limits>
#include <optional>
#include <span>

#include "loopsfm/geometry/umeyama.h"
#include "loopsfm/robust/loransac.h"

namespace loopsfm {
namespace {

double ReprojectionError(const PointObservation& obs, const Eigen::Vector3d& xyz) {
  const Eigen::Vector3d in_cam = obs.image->cam_from_world * xyz;
  if (in_cam.z() <= 1e-9) return std::numeric_limits<double>::max();
  return (obs.camera->ImgFromCam(in_cam) - obs.xy).norm();
}

// LO-RANSAC estimator of dst_from_src over point correspondences, residual: the larger of
// the two reprojection errors (source point moved into the destination frame, destination
// point moved back into the source frame), in pixels. Where the first is already above
// `max_error`, the second is not computed: the residual only has to be known to exceed the
// threshold (RANSAC's score truncates it there), which halves the work on outliers.
class Sim3AlignmentEstimator {
 public:
  using Model = Sim3d;
  static constexpr int kMinNumSamples = 3;

  Sim3AlignmentEstimator(const std::vector<PointCorrespondence>& data, double max_error)
      : data_(data), squared_max_error_(max_error * max_error) {}
  size_t NumData() const { return data_.size(); }

  std::vector<Sim3d> Estimate(std::span<const uint32_t> sample) const {
    Sim3d model;
    if (!EstimateFrom(sample, &model)) return {};
    return {model};
  }

  bool EstimateNonMinimal(std::span<const uint32_t> inliers, Sim3d* model) const {
    return EstimateFrom(inliers, model);
  }

  void Residuals(const Sim3d& dst_from_src, std::vector<double>* squared_residuals) const {
    const Sim3d src_from_dst = dst_from_src.Inverse();
    squared_residuals->resize(data_.size());
    for (size_t k = 0; k < data_.size(); ++k) {
      const PointCorrespondence& c = data_[k];
      double e = ReprojectionError(c.dst_obs, dst_from_src * c.src_xyz);
      if (e * e <= squared_max_error_) {
        e = std::max(e, ReprojectionError(c.src_obs, src_from_dst * c.dst_xyz));
      }
      (*squared_residuals)[k] = e >= 1e150 ? std::numeric_limits<double>::max() : e * e;
    }
  }

 private:
  bool EstimateFrom(std::span<const uint32_t> indices, Sim3d* model) const {
    std::vector<Eigen::Vector3d> src, dst;
    src.reserve(indices.size());
    dst.reserve(indices.size());
    for (uint32_t k : indices) {
      src.push_back(data_[k].src_xyz);
      dst.push_back(data_[k].dst_xyz);
    }
    const std::optional<Sim3d> estimate = EstimateSim3(src, dst);
    if (!estimate) return false;
    *model = *estimate;
    return true;
  }

  const std::vector<PointCorrespondence>& data_;
  double squared_max_error_;
};

}  // namespace

std::vector<char> AlignmentInliers(const std::vector<PointCorrespondence>& correspondences,
                                   const Sim3d& dst_from_src, double max_reproj_error_px) {
  std::vector<double> squared;
  Sim3AlignmentEstimator(correspondences, max_reproj_error_px).Residuals(dst_from_src, &squared);
  std::vector<char> inliers(squared.size());
  for (size_t k = 0; k < squared.size(); ++k) {
    inliers[k] = squared[k] <= max_reproj_error_px * max_reproj_error_px;
  }
  return inliers;
}

PointObservation FirstObservation(const Reconstruction& rec, const Point3D& point) {
  const TrackElement& el = point.track.elements.front();
  const Image& image = rec.GetImage(el.image_id);
  return {&image, &rec.GetCamera(image.camera_id), image.points2D[el.point2D_idx].xy};
}

PointAlignment AlignPointSets(const std::vector<PointCorrespondence>& correspondences,
                              double max_reproj_error_px, int max_num_trials, Random& random) {
  PointAlignment alignment;
  if (correspondences.size() < 3) return alignment;
  RansacOptions ransac;
  ransac.max_error = max_reproj_error_px;
  ransac.max_num_trials = max_num_trials;
  const Sim3AlignmentEstimator estimator(correspondences, max_reproj_error_px);
  auto result = LoRansac(estimator, ransac, random);
  alignment.success = result.success;
  alignment.num_inliers = result.num_inliers;
  alignment.inlier_mask = std::move(result.inlier_mask);
  alignment.dst_from_src = result.model;
  return alignment;
}

}  // namespace loopsfm
