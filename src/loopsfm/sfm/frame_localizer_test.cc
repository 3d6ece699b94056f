// The localiser on rendered frames: a keyframe with its true pose and the 3D points under
// its corners (ray cast into the synthetic world) stands in for a finished map; the frames
// after it must come out at their true poses.

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "loopsfm/sfm/frame_localizer.h"
#include "loopsfm/synth/render.h"
#include "loopsfm/synth/synthetic_scene.h"

namespace loopsfm {
namespace {

SyntheticScene StreetScene() {
  SynthOptions options;
  options.scene = "street";
  options.num_frames = 800;  // 0.14 m a frame: a brisk walk at 30 fps
  options.width = 320;
  options.height = 240;
  options.supersampling = 1;
  return MakeScene(options);
}

// Model 0 holds frame `keyframe` at its true pose, observing the surface points under its
// strongest corners.
Reconstruction KeyframeModel(const SyntheticScene& scene, int keyframe, const cv::Mat& image) {
  Reconstruction model;
  Camera camera = scene.camera;
  camera.camera_id = 1;
  model.AddCamera(camera);
  Image frame;
  frame.image_id = 1;
  frame.camera_id = 1;
  frame.name = "key";
  frame.cam_from_world = scene.world_from_cam[keyframe].Inverse();
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  std::vector<cv::Point2f> corners;
  cv::goodFeaturesToTrack(grey, corners, 400, 0.01, 6);
  for (const cv::Point2f& c : corners) {
    Point2D point;
    point.xy = Eigen::Vector2d(c.x + 0.5, c.y + 0.5);
    frame.points2D.push_back(point);
  }
  model.AddImage(frame);
  model.RegisterImage(1);
  for (point2D_t i = 0; i < model.GetImage(1).points2D.size(); ++i) {
    const auto hit = CastPixelRay(scene, keyframe, model.GetImage(1).points2D[i].xy);
    if (!hit) continue;
    Track track;
    track.elements.push_back({1, i});
    model.AddPoint3D(hit->point_in_world, track);
  }
  return model;
}

double CentreError(const Rigid3d& cam_from_world, const Rigid3d& world_from_cam) {
  return (cam_from_world.Inverse().translation - world_from_cam.translation).norm();
}

TEST(FrameLocalizer, FramesAfterAKeyframeComeOutAtTheirTruePoses) {
  const SyntheticScene scene = StreetScene();
  const cv::Mat key = RenderFrame(scene, 0);
  const std::vector<Reconstruction> models = {KeyframeModel(scene, 0, key)};
  ASSERT_GT(models[0].NumPoints3D(), 100u);
  FrameLocalizer localizer(models, FrameLocalizerOptions());
  localizer.AddKeyframe(1, key);
  for (int frame = 1; frame <= 6; ++frame) {
    const std::optional<LocalizedPose> pose = localizer.Localize(RenderFrame(scene, frame));
    ASSERT_TRUE(pose.has_value()) << "frame " << frame;
    EXPECT_EQ(pose->model, 0u);
    EXPECT_EQ(pose->camera_id, 1u);
    EXPECT_GE(pose->num_inliers, 50) << "frame " << frame;
    const Rigid3d& truth = scene.world_from_cam[frame];
    // The step is 0.14 m: centimetre errors are a tenth of it.
    EXPECT_LT(CentreError(pose->cam_from_world, truth), 0.02) << "frame " << frame;
    const Eigen::Quaterniond q = pose->cam_from_world.rotation * truth.rotation;
    EXPECT_LT(Eigen::AngleAxisd(q).angle() * 180.0 / M_PI, 0.2) << "frame " << frame;
  }
}

// Frames before any registered keyframe, or after one that no model holds, get no pose;
// an unknown keyframe does not restart tracking from nothing.
TEST(FrameLocalizer, NoPoseWithoutARegisteredKeyframe) {
  const SyntheticScene scene = StreetScene();
  const cv::Mat key = RenderFrame(scene, 0);
  const std::vector<Reconstruction> models = {KeyframeModel(scene, 0, key)};
  FrameLocalizer localizer(models, FrameLocalizerOptions());
  EXPECT_FALSE(localizer.Localize(key).has_value());
  localizer.AddKeyframe(kInvalidImageId, key);
  EXPECT_FALSE(localizer.Localize(RenderFrame(scene, 1)).has_value());
  localizer.AddKeyframe(1, key);
  localizer.AddKeyframe(kInvalidImageId, RenderFrame(scene, 1));  // tracked through
  EXPECT_TRUE(localizer.Localize(RenderFrame(scene, 2)).has_value());
}

}  // namespace
}  // namespace loopsfm
