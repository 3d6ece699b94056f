#pragma once
// A pose for every frame: the frames between keyframes (skipped by keyframe selection) are
// localised against the finished map, as SLAM systems track the frames between their
// keyframes. Fed the source's frames in order:
//   - at a keyframe registered in a model, the keypoints of that keyframe that observe a 3D
//     point become the tracked points (their 3D points known);
//   - each later frame tracks them on from the frame before (pyramidal Lucas-Kanade with a
//     forward-backward check, video/point_tracker.h) and gets its pose from the 2D-3D
//     correspondences: P3P in LO-RANSAC, then a pose-only refinement of the reprojection
//     error (estimators/absolute_pose.h) with the model's refined camera. Points that the
//     pose calls outliers are tracked no further.
// Frames may be colour (BGR) or grey. The driver (pipeline/localize.h) tries the frames that
// this gave no pose again, tracking backwards from the next keyframe.
// A keyframe that is not registered does not restart the tracking: the points go on through
// it. No feature is extracted or matched, so a frame costs a fraction of a keyframe.

#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "loopsfm/estimators/absolute_pose.h"
#include "loopsfm/math/random.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/video/point_tracker.h"

namespace loopsfm {

struct FrameLocalizerOptions {
  // P3P RANSAC and the pose refinement; the inlier threshold in pixels.
  AbsolutePoseEstimationOptions pose = [] {
    AbsolutePoseEstimationOptions o;
    o.max_error_px = 4.0;
    return o;
  }();
  // A pose needs at least this many inliers, and this fraction of the tracked points.
  int min_num_inliers = 20;
  double min_inlier_ratio = 0.5;
  PointTrackerOptions tracker;
  // Points tracked from a keyframe at most (its observations, evenly thinned): a pose needs
  // far fewer than a keyframe observes, and tracking costs per point.
  int max_tracked_points = 600;
  // Frames are tracked at most at this longer side, in pixels (keypoints scaled to it).
  int max_tracking_size = 2000;
  // The frames between two keyframes are kept (grey) up to this many bytes, for a second try
  // backwards from the next keyframe at the frames tracking forwards could not localise.
  size_t max_buffered_bytes = size_t(256) << 20;
  uint64_t seed = 0;
  void Check() const;
};

struct LocalizedPose {
  // Index of the model (in the list given to the localiser) the pose is in.
  size_t model = 0;
  camera_t camera_id = kInvalidCameraId;
  Rigid3d cam_from_world;
  int num_tracked = 0;
  int num_inliers = 0;
};

class FrameLocalizer {
 public:
  // The models must outlive the localiser.
  FrameLocalizer(const std::vector<Reconstruction>& models, const FrameLocalizerOptions& options);

  // A keyframe of the run (its image id in the models, kInvalidImageId for a frame that no
  // model knows). Restarts tracking from it when a model has it registered.
  void AddKeyframe(image_t image_id, const cv::Mat& image);
  // A frame between keyframes: its pose in the model the tracked points belong to, or
  // nullopt when too few points were tracked or the pose has too few inliers.
  std::optional<LocalizedPose> Localize(const cv::Mat& image);

 private:
  cv::Mat Grey(const cv::Mat& image);
  void Track(const cv::Mat& grey);

  const std::vector<Reconstruction>& models_;
  FrameLocalizerOptions options_;
  Random random_;
  double scale_ = 1.0;
  // What is tracked: positions in the grey frames (scaled pixels) and their 3D points.
  std::optional<size_t> model_;
  camera_t camera_id_ = kInvalidCameraId;
  std::vector<cv::Point2f> positions_;
  std::vector<point3D_t> point_ids_;
  cv::Mat previous_;
};

}  // namespace loopsfm
