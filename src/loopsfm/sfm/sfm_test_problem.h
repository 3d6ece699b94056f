#pragma once
// Test-only: small synthetic mapper problems with known answers. A camera walks along the
// x axis looking at a deep wall of points (z forward); each frame sees the points that
// project into its image, with pixel noise; pairs of frames up to `overlap` apart are
// verified pairs whose inliers are their common points, with the true relative pose.

#include <algorithm>
#include <cmath>
#include <vector>

#include "loopsfm/geometry/umeyama.h"
#include "loopsfm/math/random.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/tracks/track_builder.h"

namespace loopsfm::testing {

struct MapperProblemOptions {
  int num_frames = 30;
  int num_points = 1500;
  // Camera step along x (metres); the wall is 8-12 m away.
  double step = 0.3;
  double noise_px = 0.5;
  // Extra points on the part of the wall the first frames see (so the best initial pairs
  // lie at the start of the walk).
  int extra_points_at_start = 0;
  int overlap = 8;
  // The second half of the frames walks back along the first half (half a step beside it),
  // so its frames revisit what the first half saw: a loop. Pairs are then made between
  // frames whose centres are within `overlap` steps, however far apart in time.
  bool walk_back = false;
  // Fewest common points for a pair to be verified.
  int min_common = 20;
  uint64_t seed = 7;
};

struct MapperProblem {
  MapperInput input;
  std::vector<Rigid3d> cam_from_world;  // by frame index
  std::vector<Eigen::Vector3d> points;
  // keypoint_point[frame][k] = index of the true point of keypoint k (-1: clutter).
  std::vector<std::vector<int>> keypoint_point;
};

inline Camera TestCamera() {
  Camera camera;
  camera.camera_id = 1;
  camera.model_id = CameraModelId::kPinhole;
  camera.width = 640;
  camera.height = 480;
  camera.params = {500.0, 500.0, 320.0, 240.0};
  camera.has_prior_focal_length = true;
  return camera;
}

// Verified pair (i, j) of frame indices from the keypoints' true points.
inline MapperPair MakeTruePair(const MapperProblem& p, int i, int j) {
  MapperPair pair;
  pair.pair = ImagePair(p.input.frames[i].image_id, p.input.frames[j].image_id);
  const int a = p.input.frames[i].image_id < p.input.frames[j].image_id ? i : j;
  const int b = a == i ? j : i;
  std::vector<int> index_in_b(p.points.size(), -1);
  for (size_t k = 0; k < p.keypoint_point[b].size(); ++k) {
    if (p.keypoint_point[b][k] >= 0) index_in_b[p.keypoint_point[b][k]] = static_cast<int>(k);
  }
  for (size_t k = 0; k < p.keypoint_point[a].size(); ++k) {
    const int point = p.keypoint_point[a][k];
    if (point >= 0 && index_in_b[point] >= 0) {
      pair.geometry.inlier_matches.push_back(
          {static_cast<point2D_t>(k), static_cast<point2D_t>(index_in_b[point])});
    }
  }
  pair.geometry.config = TwoViewGeometry::kCalibrated;
  Rigid3d b_from_a = p.cam_from_world[b] * p.cam_from_world[a].Inverse();
  b_from_a.translation.normalize();
  pair.geometry.cam2_from_cam1 = b_from_a;
  return pair;
}

// Rebuilds the tracks from the pairs (call after editing pairs).
inline void RebuildTracks(MapperInput* input) {
  std::unordered_map<image_t, size_t> num_points2D;
  for (const MapperFrame& f : input->frames) num_points2D[f.image_id] = f.points2D.size();
  std::vector<VerifiedPairMatches> verified;
  for (const MapperPair& pair : input->pairs) verified.push_back({pair.pair, &pair.geometry.inlier_matches});
  input->tracks = BuildTracks(num_points2D, verified, {}, nullptr);
}

inline MapperProblem MakeMapperProblem(const MapperProblemOptions& options) {
  Random random(options.seed);
  MapperProblem p;
  const Camera camera = TestCamera();
  p.input.cameras = {camera};
  const double length =
      options.step * (options.walk_back ? options.num_frames / 2 : options.num_frames - 1);
  // Position along the walk of frame i.
  auto position = [&](int i) {
    if (!options.walk_back || i < options.num_frames / 2) return options.step * i;
    return options.step * (options.num_frames - 1 - i + 0.5);
  };
  for (int k = 0; k < options.num_points; ++k) {
    p.points.emplace_back(random.UniformReal(-7, length + 7), random.UniformReal(-3.5, 3.5),
                          random.UniformReal(8, 12));
  }
  for (int k = 0; k < options.extra_points_at_start; ++k) {
    p.points.emplace_back(random.UniformReal(-7, 2), random.UniformReal(-3.5, 3.5),
                          random.UniformReal(8, 12));
  }
  for (int i = 0; i < options.num_frames; ++i) {
    const Eigen::Quaterniond rotation =
        Eigen::AngleAxisd(random.Normal(0, 0.02), Eigen::Vector3d::UnitX()) *
        Eigen::AngleAxisd(random.Normal(0, 0.02), Eigen::Vector3d::UnitY()) *
        Eigen::Quaterniond::Identity();
    const Eigen::Vector3d centre(position(i), random.Normal(0, 0.05), random.Normal(0, 0.05));
    p.cam_from_world.emplace_back(rotation, -(rotation * centre));
    MapperFrame frame;
    frame.image_id = static_cast<image_t>(i + 1);
    frame.camera_id = camera.camera_id;
    frame.name = "frame_" + std::to_string(1000 + i);
    std::vector<std::pair<Eigen::Vector2d, int>> seen;
    for (size_t k = 0; k < p.points.size(); ++k) {
      const Eigen::Vector3d in_cam = p.cam_from_world[i] * p.points[k];
      if (in_cam.z() <= 0) continue;
      Eigen::Vector2d xy = camera.ImgFromCam(in_cam);
      if (xy.x() < 0 || xy.y() < 0 || xy.x() > camera.width || xy.y() > camera.height) continue;
      xy += Eigen::Vector2d(random.Normal(0, options.noise_px), random.Normal(0, options.noise_px));
      seen.push_back({xy, static_cast<int>(k)});
    }
    // Keypoint order unrelated to point order.
    for (size_t k = seen.size(); k > 1; --k) std::swap(seen[k - 1], seen[random.UniformInt(0, k - 1)]);
    std::vector<int> keypoint_point;
    for (const auto& [xy, point] : seen) {
      frame.points2D.push_back(xy);
      keypoint_point.push_back(point);
    }
    p.input.frames.push_back(std::move(frame));
    p.keypoint_point.push_back(std::move(keypoint_point));
  }
  for (int i = 0; i < options.num_frames; ++i) {
    for (int j = i + 1; j < options.num_frames; ++j) {
      const bool near = options.walk_back
                            ? std::abs(position(i) - position(j)) <= options.overlap * options.step
                            : j <= i + options.overlap;
      if (!near) continue;
      MapperPair pair = MakeTruePair(p, i, j);
      if (static_cast<int>(pair.geometry.inlier_matches.size()) >= options.min_common) {
        p.input.pairs.push_back(std::move(pair));
      }
    }
  }
  RebuildTracks(&p.input);
  return p;
}

// Largest camera-centre error after a similarity alignment to the truth, relative to the
// path length, over the frames registered in the model (and how many those are).
struct PoseError {
  int num_registered = 0;
  double max_centre_error = 0.0;  // fraction of the path length
  double max_rotation_deg = 0.0;
};

inline PoseError ComparePoses(const Reconstruction& rec, const MapperProblem& p) {
  std::vector<Eigen::Vector3d> estimated, truth;
  std::vector<int> frames;
  for (size_t i = 0; i < p.input.frames.size(); ++i) {
    const image_t id = p.input.frames[i].image_id;
    if (!rec.ExistsImage(id) || !rec.IsRegistered(id)) continue;
    estimated.push_back(rec.GetImage(id).ProjectionCenter());
    truth.push_back(p.cam_from_world[i].Inverse().translation);
    frames.push_back(static_cast<int>(i));
  }
  PoseError error;
  error.num_registered = static_cast<int>(frames.size());
  const auto sim3 = EstimateSim3(estimated, truth);
  if (!sim3) return {error.num_registered, 1e9, 180.0};
  const double path = (p.cam_from_world.front().Inverse().translation -
                       p.cam_from_world.back().Inverse().translation).norm();
  // Rotations relative to the first registered frame (gauge-free; the centres of a nearly
  // straight walk do not fix the rotation about the walk's axis).
  const Eigen::Quaterniond est0 = rec.GetImage(p.input.frames[frames[0]].image_id).cam_from_world.rotation;
  const Eigen::Quaterniond true0 = p.cam_from_world[frames[0]].rotation;
  for (size_t k = 0; k < frames.size(); ++k) {
    error.max_centre_error = std::max(error.max_centre_error, ((*sim3) * estimated[k] - truth[k]).norm() / path);
    const Eigen::Quaterniond est = rec.GetImage(p.input.frames[frames[k]].image_id).cam_from_world.rotation;
    const Eigen::Quaterniond relative_est = est * est0.inverse();
    const Eigen::Quaterniond relative_true = p.cam_from_world[frames[k]].rotation * true0.inverse();
    error.max_rotation_deg =
        std::max(error.max_rotation_deg, relative_est.angularDistance(relative_true) * 180.0 / M_PI);
  }
  return error;
}

}  // namespace loopsfm::testing
