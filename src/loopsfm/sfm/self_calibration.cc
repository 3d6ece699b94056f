#include "loopsfm/sfm/self_calibration.h"

#include <algorithm>
#include <unordered_map>
#include <vector>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// Index of the polynomial radial term k1 in the model's parameters; -1 for models without
// one (the pinhole models) or with an equidistant one (the fisheye models: their k1 is a
// term in the angle, not in the radius, and kappa does not convert to it).
int RadialTermIndex(CameraModelId model_id) {
  switch (model_id) {
    case CameraModelId::kSimpleRadial:
    case CameraModelId::kRadial: return 3;
    case CameraModelId::kOpenCV:
    case CameraModelId::kFullOpenCV: return 4;
    default: return -1;
  }
}

// A pair's inlier correspondences in pixels.
PairCorrespondences InlierPixels(const MapperPair& pair, const MapperFrame& frame1,
                                 const MapperFrame& frame2) {
  PairCorrespondences correspondences;
  correspondences.points1.reserve(pair.geometry.inlier_matches.size());
  correspondences.points2.reserve(pair.geometry.inlier_matches.size());
  for (const FeatureMatch& match : pair.geometry.inlier_matches) {
    correspondences.points1.push_back(frame1.points2D.at(match.point2D_idx1));
    correspondences.points2.push_back(frame2.points2D.at(match.point2D_idx2));
  }
  return correspondences;
}

using FrameLookup = std::unordered_map<image_t, const MapperFrame*>;

// The camera's uncalibrated pairs, most inliers first, at most max_num_pairs.
std::vector<const MapperPair*> UncalibratedPairs(const MapperInput& input, camera_t camera_id,
                                                 const FrameLookup& frame_of, int max_num_pairs) {
  auto camera_of = [&](image_t id) {
    const auto it = frame_of.find(id);
    LOOPSFM_CHECK_MSG(it != frame_of.end(), "pair refers to frame {} without keypoints", id);
    return it->second->camera_id;
  };
  std::vector<const MapperPair*> pairs;
  for (const MapperPair& pair : input.pairs) {
    if (pair.geometry.config == TwoViewGeometry::kUncalibrated &&
        camera_of(pair.pair.image_id1) == camera_id && camera_of(pair.pair.image_id2) == camera_id) {
      pairs.push_back(&pair);
    }
  }
  std::stable_sort(pairs.begin(), pairs.end(), [](const MapperPair* a, const MapperPair* b) {
    return a->geometry.inlier_matches.size() > b->geometry.inlier_matches.size();
  });
  if (pairs.size() > static_cast<size_t>(max_num_pairs)) pairs.resize(max_num_pairs);
  return pairs;
}

// The focal length (and, where the model has one and the options ask, the radial term) of
// one camera from its pairs; the camera takes them when the estimate succeeds.
CameraSelfCalibration CalibrateCamera(const std::vector<const MapperPair*>& pairs,
                                      const FrameLookup& frame_of,
                                      const SelfCalibrationOptions& options, Camera* camera) {
  CameraSelfCalibration entry;
  entry.camera_id = camera->camera_id;
  entry.initial_focal_px = entry.focal_px = camera->MeanFocalLength();
  std::vector<Eigen::Matrix3d> fundamentals;
  std::vector<double> weights;
  for (const MapperPair* pair : pairs) {
    fundamentals.push_back(pair->geometry.F);
    weights.push_back(static_cast<double>(pair->geometry.inlier_matches.size()));
  }
  const Eigen::Vector2d principal_point(camera->width / 2.0, camera->height / 2.0);
  const double radius_unit = DistortionRadiusUnit(camera->width, camera->height);
  const int radial_index = RadialTermIndex(camera->model_id);
  if (options.estimate_distortion && radial_index >= 0) {
    std::vector<PairCorrespondences> correspondences;
    correspondences.reserve(pairs.size());
    for (const MapperPair* pair : pairs) {
      correspondences.push_back(InlierPixels(*pair, *frame_of.at(pair->pair.image_id1),
                                             *frame_of.at(pair->pair.image_id2)));
    }
    entry.distortion_estimated = true;
    entry.distortion = EstimateRadialDistortion(correspondences, principal_point, camera->width,
                                                camera->height, options.distortion);
    if (entry.distortion.significant) {
      // The verified F were fitted to distorted points: fit them again to undistorted ones.
      fundamentals = UndistortedFundamentals(correspondences, principal_point, radius_unit,
                                             entry.distortion.kappa,
                                             options.distortion.error_cap_px);
    } else {
      spdlog::info("self-calibration: camera {} keeps k1 = 0: {}", camera->camera_id,
                   entry.distortion.explanation);
    }
  }
  entry.estimate = EstimateSharedFocalLength(fundamentals, weights, principal_point,
                                             camera->width, camera->height, options.focal);
  if (!entry.estimate.success) {
    spdlog::warn("self-calibration: camera {} keeps its guessed focal length {:.1f} px: {}; "
                 "bundle adjustment refines it, or pass --intrinsics",
                 camera->camera_id, entry.initial_focal_px, entry.estimate.explanation);
    return entry;
  }
  // The estimate assumes the principal point at the centre: put it there.
  camera->params = Camera::GuessFromImageSize(camera->width, camera->height, camera->model_id).params;
  camera->SetFocalLength(entry.estimate.focal_px);
  entry.focal_px = entry.estimate.focal_px;
  entry.applied = true;
  if (entry.distortion.significant) {
    entry.k1 = RadialTermForFocalLength(entry.distortion.kappa, entry.focal_px, radius_unit);
    camera->params.at(radial_index) = entry.k1;
    spdlog::info("self-calibration: camera {} radial term k1 {:.4f} (kappa {:.4f}: epipolar "
                 "error {:.3f} px, {:.3f} px without, over {} pairs)",
                 camera->camera_id, entry.k1, entry.distortion.kappa, entry.distortion.error_px,
                 entry.distortion.error_px_without, entry.distortion.num_pairs_used);
  }
  spdlog::info("self-calibration: camera {} focal length {:.1f} px (guess {:.1f}), spread "
               "{:.2f} %, {} of {} pairs agree ({} usable)",
               camera->camera_id, entry.focal_px, entry.initial_focal_px,
               100.0 * entry.estimate.spread, entry.estimate.num_pairs_inlier,
               entry.estimate.num_pairs, entry.estimate.num_pairs_used);
  return entry;
}

}  // namespace

void SelfCalibrationOptions::Check() const {
  focal.Check();
  distortion.Check();
  verification.Check();
  LOOPSFM_REQUIRE_OPTION(max_num_pairs > 0, "self-calibration max_num_pairs must be positive, got {}",
                         max_num_pairs);
}

SelfCalibrationReport SelfCalibrate(const SelfCalibrationOptions& options, MapperInput* input) {
  options.Check();
  Timer timer;
  SelfCalibrationReport report;
  FrameLookup frame_of;
  for (const MapperFrame& frame : input->frames) frame_of[frame.image_id] = &frame;
  std::unordered_map<camera_t, Camera*> calibrated;
  for (Camera& camera : input->cameras) {
    if (camera.has_prior_focal_length) continue;
    const std::vector<const MapperPair*> pairs =
        UncalibratedPairs(*input, camera.camera_id, frame_of, options.max_num_pairs);
    report.cameras.push_back(CalibrateCamera(pairs, frame_of, options, &camera));
    if (report.cameras.back().applied) calibrated[camera.camera_id] = &camera;
  }
  // The relative poses of the pairs of calibrated cameras, again with the new intrinsics.
  if (!calibrated.empty()) {
    std::unordered_map<camera_t, const Camera*> cameras;
    for (const Camera& camera : input->cameras) cameras[camera.camera_id] = &camera;
    for (MapperPair& pair : input->pairs) {
      const MapperFrame& frame1 = *frame_of.at(pair.pair.image_id1);
      const MapperFrame& frame2 = *frame_of.at(pair.pair.image_id2);
      if (!calibrated.count(frame1.camera_id) && !calibrated.count(frame2.camera_id)) continue;
      UpdateRelativePose(*cameras.at(frame1.camera_id), frame1.points2D,
                         *cameras.at(frame2.camera_id), frame2.points2D, options.verification,
                         &pair.geometry);
      ++report.num_pairs_updated;
    }
  }
  report.seconds = timer.ElapsedSeconds();
  return report;
}

}  // namespace loopsfm
