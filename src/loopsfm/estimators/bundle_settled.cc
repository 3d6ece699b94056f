#include "loopsfm/estimators/bundle_settled.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace loopsfm {

double CentreSpread(const std::vector<Eigen::Vector3d>& centres) {
  if (centres.empty()) return 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& c : centres) mean += c;
  mean /= static_cast<double>(centres.size());
  double sum = 0.0;
  for (const Eigen::Vector3d& c : centres) sum += (c - mean).squaredNorm();
  return std::sqrt(sum / static_cast<double>(centres.size()));
}

SettledCallback::SettledCallback(const Reconstruction& reconstruction,
                                 std::vector<image_t> image_ids,
                                 std::vector<camera_t> camera_ids, double tolerance)
    : reconstruction_(reconstruction),
      image_ids_(std::move(image_ids)),
      camera_ids_(std::move(camera_ids)),
      tolerance_(tolerance) {
  Snapshot();
  spread_ = CentreSpread(centres_);
}

ceres::CallbackReturnType SettledCallback::operator()(const ceres::IterationSummary& summary) {
  if (summary.iteration == 0 || !summary.step_is_successful || spread_ <= 0.0) {
    return ceres::SOLVER_CONTINUE;
  }
  std::vector<Eigen::Vector3d> centres;
  std::vector<Eigen::Quaterniond> rotations;
  std::vector<double> params;
  centres.swap(centres_);
  rotations.swap(rotations_);
  params.swap(params_);
  Snapshot();
  double max_move = 0.0, max_turn = 0.0, max_change = 0.0;
  for (size_t i = 0; i < centres_.size(); ++i) {
    max_move = std::max(max_move, (centres_[i] - centres[i]).norm());
    max_turn = std::max(max_turn, rotations_[i].angularDistance(rotations[i]));
  }
  for (size_t i = 0; i < params_.size(); ++i) {
    max_change = std::max(max_change,
                          std::abs(params_[i] - params[i]) / std::max(std::abs(params[i]), 1.0));
  }
  const bool settled =
      max_move <= tolerance_ * spread_ && max_turn <= tolerance_ && max_change <= tolerance_;
  num_settled_ = settled ? num_settled_ + 1 : 0;
  return num_settled_ >= 2 ? ceres::SOLVER_TERMINATE_SUCCESSFULLY : ceres::SOLVER_CONTINUE;
}

void SettledCallback::Snapshot() {
  centres_.clear();
  rotations_.clear();
  params_.clear();
  for (const image_t id : image_ids_) {
    const Rigid3d& pose = reconstruction_.GetImage(id).cam_from_world;
    const Eigen::Quaterniond rotation = pose.rotation.normalized();
    rotations_.push_back(rotation);
    centres_.push_back(-(rotation.inverse() * pose.translation));
  }
  for (const camera_t id : camera_ids_) {
    const std::vector<double>& values = reconstruction_.GetCamera(id).params;
    params_.insert(params_.end(), values.begin(), values.end());
  }
}

}  // namespace loopsfm
