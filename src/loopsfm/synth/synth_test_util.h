#pragma once
// Helpers shared by the synth tests.

#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "loopsfm/synth/synthetic_scene.h"

namespace loopsfm::synth_test {

inline SynthOptions SmallOptions(const std::string& scene) {
  SynthOptions options;
  options.scene = scene;
  options.num_frames = 12;
  options.width = 320;
  options.height = 240;
  return options;
}

// An empty temporary folder (unique to this process), removed at the end of the test.
class TempDir {
 public:
  explicit TempDir(const std::string& name)
      : path_(std::filesystem::temp_directory_path() /
              ("loopsfm_synth_test_" + std::to_string(::getpid()) + "_" + name)) {
    std::filesystem::remove_all(path_);
  }
  ~TempDir() {
    std::error_code error;
    std::filesystem::remove_all(path_, error);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

inline Eigen::Vector2d Project(const SyntheticScene& scene, int frame,
                               const Eigen::Vector3d& point) {
  const Eigen::Vector3d in_cam = scene.world_from_cam[frame].Inverse() * point;
  return scene.camera.ImgFromCam(in_cam);
}

inline bool InImage(const SyntheticScene& scene, const Eigen::Vector2d& xy) {
  return xy.x() > 0 && xy.y() > 0 && xy.x() < scene.camera.width &&
         xy.y() < scene.camera.height;
}

inline int CountSift(const cv::Mat& image) {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  cv::SIFT::create()->detect(gray, keypoints);
  return static_cast<int>(keypoints.size());
}

}  // namespace loopsfm::synth_test
