#pragma once
// Top-view plot of camera paths (PNG): the paths are projected onto the plane of the two
// largest principal axes of the first path's centres (the ground plane of a walk or a
// drive), drawn on one scale with a legend, and optional segments (e.g. the two ends of a
// loop) drawn as thin lines.
//
//   WriteTopView("top.png", {{"ground truth", gt_centres, kGrey}, {"estimate", est, kBlue}},
//                {}, "block.mp4, --loop-closing none");
#include <array>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace loopsfm {

// The plane seen from above: the two largest principal axes of a set of camera centres
// through their mean (the ground plane of a walk or a drive).
struct TopViewPlane {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis_u = Eigen::Vector3d::UnitX();
  Eigen::Vector3d axis_v = Eigen::Vector3d::UnitY();
  // Coordinates of x along the two axes, relative to the mean.
  Eigen::Vector2d Project(const Eigen::Vector3d& x) const {
    return {(x - mean).dot(axis_u), (x - mean).dot(axis_v)};
  }
};

// The plane of `centres` (at least one).
TopViewPlane FitTopViewPlane(const std::vector<Eigen::Vector3d>& centres);

struct TopViewPath {
  std::string label;
  std::vector<Eigen::Vector3d> centres;  // in order, in one world frame for all paths
  std::array<unsigned char, 3> rgb = {0, 0, 0};
};

struct TopViewSegments {
  std::string label;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> segments;
  std::array<unsigned char, 3> rgb = {0, 0, 0};
};

// Throws InvalidArgument when there is nothing to plot (no path with two centres) or the
// file cannot be written.
void WriteTopView(const std::filesystem::path& file, const std::vector<TopViewPath>& paths,
                  const std::vector<TopViewSegments>& segments, const std::string& title,
                  int size_px = 900);

}  // namespace loopsfm
