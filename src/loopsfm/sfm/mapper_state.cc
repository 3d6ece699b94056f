#include "loopsfm/sfm/mapper_state.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "loopsfm/estimators/reprojection.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

MapperState::MapperState(const MapperInput& input, const IncrementalMapperOptions& options)
    : MapStructure(input, options) {
  for (const MapperPair& pair : input.pairs) {
    pairs_of_[pair.pair.image_id1].push_back(&pair);
    pairs_of_[pair.pair.image_id2].push_back(&pair);
  }
}

MapperCheckpoint::Model MapperState::Save() const {
  return {reconstruction_.SaveMapped(), gauge1_, gauge2_, 0};
}

void MapperState::Restore(const MapperCheckpoint::Model& saved) {
  reconstruction_.RestoreMapped(saved.state);
  for (const image_t id : {saved.gauge1, saved.gauge2}) {
    if (!reconstruction_.ExistsImage(id) || !reconstruction_.IsRegistered(id)) {
      throw InputError(fmt::format("saved gauge frame {} is not registered in its model", id));
    }
  }
  SetGauge(saved.gauge1, saved.gauge2);
}

void MapperState::SetGauge(image_t first, image_t second) {
  gauge1_ = first;
  gauge2_ = second;
}

std::vector<image_t> MapperState::TakeFramesOf(const Reconstruction& model) {
  for (const auto& [id, camera] : model.Cameras()) reconstruction_.GetCamera(id) = camera;
  std::vector<image_t> ordered;
  for (const MapperFrame& frame : input_.frames) {
    if (!model.ExistsImage(frame.image_id) || !model.IsRegistered(frame.image_id)) continue;
    reconstruction_.GetImage(frame.image_id).cam_from_world =
        model.GetImage(frame.image_id).cam_from_world;
    reconstruction_.RegisterImage(frame.image_id);
    ordered.push_back(frame.image_id);
  }
  if (ordered.size() >= 2) SetGauge(ordered[0], ordered[1]);
  return ordered;
}

bool MapperState::NearRegisteredFrame(image_t image_id, int window) const {
  const int index = capture_index_.at(image_id);
  const int last = static_cast<int>(input_.frames.size()) - 1;
  for (int k = std::max(0, index - window); k <= std::min(last, index + window); ++k) {
    if (k != index && reconstruction_.IsRegistered(input_.frames[k].image_id)) return true;
  }
  return false;
}

std::vector<std::tuple<int, image_t, const MapperPair*>> MapperState::RegisteredPartnersNear(
    image_t image_id) const {
  std::vector<std::tuple<int, image_t, const MapperPair*>> near;
  const int window = options_.registration_neighbour_window;
  const auto pairs = pairs_of_.find(image_id);
  if (window <= 0 || pairs == pairs_of_.end()) return near;
  const int index = capture_index_.at(image_id);
  for (const MapperPair* pair : pairs->second) {
    const image_t other =
        pair->pair.image_id1 == image_id ? pair->pair.image_id2 : pair->pair.image_id1;
    const int distance = std::abs(capture_index_.at(other) - index);
    if (distance <= window && reconstruction_.IsRegistered(other)) {
      near.push_back({distance, other, pair});
    }
  }
  return near;
}

std::vector<std::pair<point2D_t, point3D_t>> MapperState::NeighbourCorrespondences(
    image_t image_id) const {
  std::vector<std::pair<point2D_t, point3D_t>> correspondences;
  std::vector<std::tuple<int, image_t, const MapperPair*>> near = RegisteredPartnersNear(image_id);
  std::sort(near.begin(), near.end());
  if (near.size() > 2) near.resize(2);
  for (const auto& [distance, other, pair] : near) {
    const bool first = pair->pair.image_id1 == image_id;
    const Image& other_image = reconstruction_.GetImage(other);
    for (const FeatureMatch& match : pair->geometry.inlier_matches) {
      const point2D_t own = first ? match.point2D_idx1 : match.point2D_idx2;
      const point2D_t theirs = first ? match.point2D_idx2 : match.point2D_idx1;
      const point3D_t point = other_image.points2D[theirs].point3D_id;
      if (point != kInvalidPoint3DId) correspondences.push_back({own, point});
    }
  }
  return correspondences;
}

MapperState::NeighbourAgreement MapperState::AgreementWithNeighbours(
    image_t image_id, const Rigid3d& cam_from_world,
    const std::vector<std::pair<point2D_t, point3D_t>>& correspondences) const {
  NeighbourAgreement agreement;
  const Image& image = reconstruction_.GetImage(image_id);
  const Camera& camera = reconstruction_.GetCamera(image.camera_id);
  const double max_error_sq = options_.abs_pose_max_error_px * options_.abs_pose_max_error_px;
  for (const auto& [own, point] : correspondences) {
    ++agreement.num_checked;
    agreement.num_fit += CalculateSquaredReprojectionError(
                             image.points2D[own].xy, reconstruction_.GetPoint3D(point).xyz,
                             cam_from_world, camera) <= max_error_sq;
  }
  return agreement;
}

}  // namespace loopsfm
