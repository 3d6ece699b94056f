#include "loopsfm/sfm/frame_localizer.h"

#include "loopsfm/util/errors.h"

namespace loopsfm {

void FrameLocalizerOptions::Check() const {
  pose.Check();
  LOOPSFM_REQUIRE_OPTION(min_num_inliers >= 4, "localisation needs at least 4 inliers, got {}",
                         min_num_inliers);
  LOOPSFM_REQUIRE_OPTION(min_inlier_ratio >= 0.0 && min_inlier_ratio <= 1.0,
                         "localisation: inlier ratio must be in [0, 1], got {}", min_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(max_tracked_points >= min_num_inliers,
                         "localisation: max_tracked_points ({}) below min_num_inliers ({})",
                         max_tracked_points, min_num_inliers);
  LOOPSFM_REQUIRE_OPTION(max_tracking_size >= 64,
                         "localisation: tracking size must be at least 64 px, got {}",
                         max_tracking_size);
}

FrameLocalizer::FrameLocalizer(const std::vector<Reconstruction>& models,
                               const FrameLocalizerOptions& options)
    : models_(models), options_(options), random_(options.seed) {
  options_.Check();
}

cv::Mat FrameLocalizer::Grey(const cv::Mat& image) {
  return GreyForTracking(image, options_.max_tracking_size, &scale_);
}

void FrameLocalizer::AddKeyframe(image_t image_id, const cv::Mat& image) {
  const cv::Mat grey = Grey(image);
  for (size_t m = 0; m < models_.size(); ++m) {
    const Reconstruction& model = models_[m];
    if (!model.ExistsImage(image_id) || !model.IsRegistered(image_id)) continue;
    const Image& keyframe = model.GetImage(image_id);
    model_ = m;
    camera_id_ = keyframe.camera_id;
    positions_.clear();
    point_ids_.clear();
    size_t num_observed = 0;
    for (const Point2D& point : keyframe.points2D) num_observed += point.HasPoint3D();
    const size_t stride =
        (num_observed + options_.max_tracked_points - 1) / options_.max_tracked_points;
    size_t k = 0;
    for (const Point2D& point : keyframe.points2D) {
      if (!point.HasPoint3D() || k++ % stride != 0) continue;
      // Keypoints are in COLMAP's convention (pixel centres at +0.5), OpenCV's at 0.
      positions_.emplace_back(static_cast<float>(scale_ * point.xy.x() - 0.5),
                              static_cast<float>(scale_ * point.xy.y() - 0.5));
      point_ids_.push_back(point.point3D_id);
    }
    previous_ = grey;
    return;
  }
  // Not in any model: the tracked points go on through it.
  Track(grey);
}

void FrameLocalizer::Track(const cv::Mat& grey) {
  if (!positions_.empty() && !previous_.empty()) {
    std::vector<cv::Point2f> next;
    std::vector<unsigned char> ok;
    TrackPoints(previous_, grey, positions_, options_.tracker, &next, &ok);
    size_t kept = 0;
    for (size_t i = 0; i < ok.size(); ++i) {
      if (!ok[i]) continue;
      positions_[kept] = next[i];
      point_ids_[kept] = point_ids_[i];
      ++kept;
    }
    positions_.resize(kept);
    point_ids_.resize(kept);
  }
  previous_ = grey;
}

std::optional<LocalizedPose> FrameLocalizer::Localize(const cv::Mat& image) {
  Track(Grey(image));
  if (!model_ || static_cast<int>(positions_.size()) < options_.min_num_inliers) {
    return std::nullopt;
  }
  const Reconstruction& model = models_[*model_];
  std::vector<Eigen::Vector2d> points2D;
  std::vector<Eigen::Vector3d> points3D;
  points2D.reserve(positions_.size());
  points3D.reserve(positions_.size());
  for (size_t i = 0; i < positions_.size(); ++i) {
    points2D.emplace_back((positions_[i].x + 0.5) / scale_, (positions_[i].y + 0.5) / scale_);
    points3D.push_back(model.GetPoint3D(point_ids_[i]).xyz);
  }
  const AbsolutePoseReport pose = EstimateAbsolutePose(
      points2D, points3D, model.GetCamera(camera_id_), options_.pose, random_);
  if (!pose.success) return std::nullopt;
  // Outliers are tracked no further: they drifted onto something else.
  size_t kept = 0;
  for (size_t i = 0; i < positions_.size(); ++i) {
    if (!pose.inlier_mask[i]) continue;
    positions_[kept] = positions_[i];
    point_ids_[kept] = point_ids_[i];
    ++kept;
  }
  const int tracked = static_cast<int>(positions_.size());
  positions_.resize(kept);
  point_ids_.resize(kept);
  if (pose.num_inliers < options_.min_num_inliers ||
      pose.num_inliers < options_.min_inlier_ratio * tracked) {
    return std::nullopt;
  }
  return LocalizedPose{*model_, camera_id_, pose.cam_from_world, tracked, pose.num_inliers};
}

}  // namespace loopsfm
