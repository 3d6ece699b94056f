#include "loopsfm/sfm/model_merger.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "loopsfm/geometry/umeyama.h"
#include "loopsfm/robust/loransac.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm {
namespace {

struct Observation {
  const Image* image = nullptr;
  const Camera* camera = nullptr;
  Eigen::Vector2d xy;
};

struct Correspondence {
  Eigen::Vector3d src_xyz, dst_xyz;
  Observation src_obs, dst_obs;
};

Observation FirstObservation(const Reconstruction& rec, const Point3D& point) {
  const TrackElement& el = point.track.elements.front();
  const Image& image = rec.GetImage(el.image_id);
  return {&image, &rec.GetCamera(image.camera_id), image.points2D[el.point2D_idx].xy};
}

double ReprojectionError(const Observation& obs, const Eigen::Vector3d& xyz) {
  const Eigen::Vector3d in_cam = obs.image->cam_from_world * xyz;
  if (in_cam.z() <= 1e-9) return std::numeric_limits<double>::max();
  return (obs.camera->ImgFromCam(in_cam) - obs.xy).norm();
}

// LO-RANSAC estimator of dst_from_src over point correspondences, residual: the larger of
// the two reprojection errors (source point moved into the destination frame, destination
// point moved back into the source frame), in pixels.
class Sim3AlignmentEstimator {
 public:
  using Model = Sim3d;
  static constexpr int kMinNumSamples = 3;

  explicit Sim3AlignmentEstimator(const std::vector<Correspondence>& data) : data_(data) {}
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
      const Correspondence& c = data_[k];
      const double e = std::max(ReprojectionError(c.dst_obs, dst_from_src * c.src_xyz),
                                ReprojectionError(c.src_obs, src_from_dst * c.dst_xyz));
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

  const std::vector<Correspondence>& data_;
};

std::vector<Correspondence> CommonTrackPoints(const MapperState& dst, const MapperState& src) {
  const Reconstruction& d = dst.reconstruction();
  const Reconstruction& s = src.reconstruction();
  std::vector<Correspondence> correspondences;
  for (const auto& [id, point] : s.Points3D()) {
    const int track = src.TrackOfPoint(id);
    for (point3D_t other : dst.PointsOfTrack(track)) {
      const Point3D& q = d.GetPoint3D(other);
      correspondences.push_back({point.xyz, q.xyz, FirstObservation(s, point), FirstObservation(d, q)});
    }
  }
  return correspondences;
}

}  // namespace

ModelMergeReport MergeModels(MapperState& dst, const MapperState& src, Random& random) {
  LOOPSFM_CHECK(&dst.input() == &src.input());
  const IncrementalMapperOptions& options = dst.options();
  ModelMergeReport report;
  const std::vector<Correspondence> correspondences = CommonTrackPoints(dst, src);
  report.num_correspondences = static_cast<int>(correspondences.size());
  if (report.num_correspondences < options.merge_min_num_inliers) return report;

  RansacOptions ransac;
  ransac.max_error = options.merge_max_reproj_error_px;
  ransac.max_num_trials = 2000;
  const Sim3AlignmentEstimator estimator(correspondences);
  const auto result = LoRansac(estimator, ransac, random);
  report.num_inliers = result.num_inliers;
  if (!result.success || result.num_inliers < options.merge_min_num_inliers ||
      result.num_inliers < options.merge_min_inlier_ratio * report.num_correspondences) {
    return report;
  }
  report.success = true;
  report.dst_from_src = result.model;

  // Frames the destination lacks, with their moved poses.
  Reconstruction& d = dst.reconstruction();
  const Reconstruction& s = src.reconstruction();
  for (image_t id : s.RegImageIds()) {
    if (d.IsRegistered(id)) continue;
    d.GetImage(id).cam_from_world = TransformCamFromWorld(s.GetImage(id).cam_from_world, result.model);
    d.RegisterImage(id);
    ++report.num_images_added;
  }
  // Points: observations the destination has no point for join a point of their track they
  // fit, or make a point of their own.
  for (const auto& [id, point] : s.Points3D()) {
    std::vector<TrackElement> free;
    for (const TrackElement& el : point.track.elements) {
      if (!d.GetImage(el.image_id).points2D[el.point2D_idx].HasPoint3D()) free.push_back(el);
    }
    if (free.empty()) continue;
    const Eigen::Vector3d xyz = result.model * point.xyz;
    bool joined = false;
    for (point3D_t other : dst.PointsOfTrack(src.TrackOfPoint(id))) {
      const Eigen::Vector3d& at = d.GetPoint3D(other).xyz;
      const bool fits = std::all_of(free.begin(), free.end(), [&](const TrackElement& el) {
        return dst.ReprojectionErrorPx(at, el) <= options.max_reproj_error_px;
      });
      if (!fits) continue;
      for (const TrackElement& el : free) d.AddObservation(other, el);
      ++report.num_points_joined;
      joined = true;
      break;
    }
    if (!joined && free.size() >= 2) {
      Track track;
      track.elements = free;
      d.AddPoint3D(xyz, track, point.color);
      ++report.num_points_added;
    }
  }
  return report;
}

}  // namespace loopsfm
