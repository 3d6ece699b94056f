#include "loopsfm/sfm/incremental_mapper.h"

#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "loopsfm/estimators/absolute_pose.h"
#include "loopsfm/estimators/bundle_adjustment.h"
#include "loopsfm/geometry/triangulation.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

void IncrementalMapperOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(init_min_num_inliers >= 8, "initial pair needs at least 8 inliers, got {}",
                         init_min_num_inliers);
  LOOPSFM_REQUIRE_OPTION(init_max_h_inlier_ratio > 0 && init_max_h_inlier_ratio <= 1,
                         "initial homography inlier ratio must be in (0, 1], got {}",
                         init_max_h_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(abs_pose_max_error_px > 0, "registration error threshold must be positive");
  LOOPSFM_REQUIRE_OPTION(abs_pose_min_num_inliers >= 4, "registration needs at least 4 inliers");
  LOOPSFM_REQUIRE_OPTION(max_reproj_error_px > 0, "reprojection error threshold must be positive");
  LOOPSFM_REQUIRE_OPTION(min_tri_angle_deg >= 0, "triangulation angle must not be negative");
  LOOPSFM_REQUIRE_OPTION(local_ba_num_images >= 1, "local bundle needs at least one image");
  LOOPSFM_REQUIRE_OPTION(global_ba_growth > 0, "global bundle growth must be positive");
  LOOPSFM_REQUIRE_OPTION(max_num_models >= 1, "at least one model must be allowed");
}

namespace {

struct InitialPair {
  image_t image_id1, image_id2;
  const MapperPair* pair;
  double tri_angle_deg;
  double h_ratio;
};

// Fraction of a pair's inliers that its homography maps within max_error pixels.
double HomographyInlierRatio(const MapperPair& pair, const MapperFrame& f1, const MapperFrame& f2,
                             double max_error) {
  const auto& inliers = pair.geometry.inlier_matches;
  if (inliers.empty() || pair.geometry.H.isZero()) return 0.0;
  size_t count = 0;
  for (const FeatureMatch& m : inliers) {
    const Eigen::Vector3d x2 = pair.geometry.H * f1.points2D[m.point2D_idx1].homogeneous();
    if (std::abs(x2.z()) > 1e-12 &&
        (x2.hnormalized() - f2.points2D[m.point2D_idx2]).norm() <= max_error) {
      ++count;
    }
  }
  return double(count) / inliers.size();
}

class IncrementalMapper {
 public:
  IncrementalMapper(const MapperInput& input, const IncrementalMapperOptions& options,
                    MapperReport* report, const MapperProgress& progress)
      : input_(input), options_(options), report_(*report), progress_(progress) {
    for (size_t i = 0; i < input.frames.size(); ++i) frame_index_[input.frames[i].image_id] = i;
    for (const Camera& camera : input.cameras) camera_of_id_[camera.camera_id] = camera;
  }

  std::vector<Reconstruction> Run() {
    std::vector<Reconstruction> models;
    std::vector<InitialPair> candidates = InitialPairCandidates();
    size_t next_candidate = 0;
    while (static_cast<int>(models.size()) < options_.max_num_models) {
      std::optional<Reconstruction> model;
      while (!model && next_candidate < candidates.size()) {
        const InitialPair& init = candidates[next_candidate++];
        if (used_.count(init.image_id1) || used_.count(init.image_id2)) continue;
        model = GrowModel(init);
      }
      if (!model) break;
      for (image_t id : model->RegImageIds()) used_.insert(id);
      if (static_cast<int>(model->NumRegImages()) >= options_.min_model_size) {
        models.push_back(std::move(*model));
      }
      if (used_.size() + options_.min_model_size > input_.frames.size()) break;
    }
    std::sort(models.begin(), models.end(), [](const Reconstruction& a, const Reconstruction& b) {
      return a.NumRegImages() > b.NumRegImages();
    });
    report_.num_models = static_cast<int>(models.size());
    return models;
  }

 private:
  // Initial pairs in the order they are tried. For video (capture order) the first frame
  // is paired with the first later frame whose matches a homography no longer explains and
  // that has enough triangulation angle; then every other good pair, most inliers first.
  std::vector<InitialPair> InitialPairCandidates() const {
    std::vector<InitialPair> good, fallback;
    for (const MapperPair& pair : input_.pairs) {
      const auto& g = pair.geometry;
      if (static_cast<int>(g.inlier_matches.size()) < options_.init_min_num_inliers) continue;
      const MapperFrame& f1 = input_.frames[frame_index_.at(pair.pair.image_id1)];
      const MapperFrame& f2 = input_.frames[frame_index_.at(pair.pair.image_id2)];
      const double h_ratio = HomographyInlierRatio(pair, f1, f2, options_.max_reproj_error_px);
      const double angle = MedianTriangulationAngleDeg(pair, f1, f2);
      spdlog::debug("initial pair candidate {} - {}: {} inliers, config {}, H ratio {:.2f}, {:.1f} deg",
                    f1.name, f2.name, g.inlier_matches.size(), g.config, h_ratio, angle);
      if (angle < options_.init_min_tri_angle_deg) continue;
      const InitialPair candidate{pair.pair.image_id1, pair.pair.image_id2, &pair, angle, h_ratio};
      (h_ratio <= options_.init_max_h_inlier_ratio ? good : fallback).push_back(candidate);
    }
    // Video start first: the earliest frame with the earliest partner that passes.
    std::sort(good.begin(), good.end(), [&](const InitialPair& a, const InitialPair& b) {
      const size_t a1 = frame_index_.at(a.image_id1), b1 = frame_index_.at(b.image_id1);
      if (a1 != b1) return a1 < b1;
      return frame_index_.at(a.image_id2) < frame_index_.at(b.image_id2);
    });
    // Then every other passing pair, most inliers first.
    if (good.size() > 1) {
      std::sort(good.begin() + 1, good.end(), [](const InitialPair& a, const InitialPair& b) {
        return a.pair->geometry.inlier_matches.size() > b.pair->geometry.inlier_matches.size();
      });
    }
    // Scenes dominated by one plane (a textured floor) may have no pair below the homography
    // ratio: then the least planar pairs, which still hold off-plane points.
    std::sort(fallback.begin(), fallback.end(), [](const InitialPair& a, const InitialPair& b) {
      return a.h_ratio < b.h_ratio;
    });
    good.insert(good.end(), fallback.begin(), fallback.end());
    return good;
  }

  double MedianTriangulationAngleDeg(const MapperPair& pair, const MapperFrame& f1,
                                     const MapperFrame& f2) const {
    const Camera& c1 = camera_of_id_.at(f1.camera_id);
    const Camera& c2 = camera_of_id_.at(f2.camera_id);
    const Matrix3x4d pose1 = Rigid3d().ToMatrix();
    const Matrix3x4d pose2 = pair.geometry.cam2_from_cam1.ToMatrix();
    const Eigen::Vector3d center2 = pair.geometry.cam2_from_cam1.Inverse().translation;
    std::vector<double> angles;
    const auto& inliers = pair.geometry.inlier_matches;
    const size_t step = std::max<size_t>(1, inliers.size() / 200);
    for (size_t i = 0; i < inliers.size(); i += step) {
      const auto xyz = TriangulatePoint(pose1, pose2, c1.CamFromImg(f1.points2D[inliers[i].point2D_idx1]),
                                        c2.CamFromImg(f2.points2D[inliers[i].point2D_idx2]));
      if (xyz) angles.push_back(CalculateTriangulationAngle(Eigen::Vector3d::Zero(), center2, *xyz));
    }
    if (angles.empty()) return 0.0;
    std::nth_element(angles.begin(), angles.begin() + angles.size() / 2, angles.end());
    return angles[angles.size() / 2] * 180.0 / M_PI;
  }

  std::optional<Reconstruction> GrowModel(const InitialPair& init) {
    MapperState state(input_, options_);
    Reconstruction& rec = state.reconstruction();
    // Two-view start: first camera at the origin, second at the verified relative pose.
    rec.GetImage(init.image_id1).cam_from_world = Rigid3d();
    rec.GetImage(init.image_id2).cam_from_world = init.pair->geometry.cam2_from_cam1;
    rec.RegisterImage(init.image_id1);
    rec.RegisterImage(init.image_id2);
    init1_ = init.image_id1;
    init2_ = init.image_id2;
    state.TriangulateImage(init.image_id2);
    GlobalBundle(state);
    state.FilterPoints({});
    if (rec.NumPoints3D() < static_cast<size_t>(options_.abs_pose_min_num_inliers)) {
      spdlog::debug("initial pair {} - {} gave only {} points; trying another", init.image_id1,
                    init.image_id2, rec.NumPoints3D());
      return std::nullopt;
    }
    spdlog::info("model {}: initial pair {} + {} ({:.1f} deg, homography ratio {:.2f}, {} points)",
                 report_.num_models + 1, rec.GetImage(init.image_id1).name,
                 rec.GetImage(init.image_id2).name, init.tri_angle_deg, init.h_ratio,
                 rec.NumPoints3D());

    std::unordered_map<image_t, int> trials;
    size_t last_global_size = rec.NumRegImages();
    Random random(options_.seed);
    while (true) {
      const auto visible = state.CountVisiblePoints();
      std::vector<std::pair<size_t, image_t>> order;
      for (const auto& [id, count] : visible) {
        if (used_.count(id) || trials[id] >= options_.max_registration_trials) continue;
        if (count >= static_cast<size_t>(options_.abs_pose_min_num_inliers)) order.push_back({count, id});
      }
      std::sort(order.begin(), order.end(), std::greater<>());
      bool registered = false;
      for (const auto& [count, image_id] : order) {
        if (RegisterImage(state, image_id, random)) {
          registered = true;
          Timer tri_timer;
          state.TriangulateImage(image_id);
          report_.seconds_triangulation += tri_timer.ElapsedSeconds();
          LocalBundle(state, image_id);
          if (rec.NumRegImages() >= last_global_size * (1.0 + options_.global_ba_growth)) {
            GlobalRefinement(state);
            last_global_size = rec.NumRegImages();
          }
          if (progress_) progress_(rec.NumRegImages(), input_.frames.size());
          break;
        }
        ++trials[image_id];
      }
      if (!registered) break;
    }
    GlobalRefinement(state);
    rec.UpdateReprojectionErrors();
    return std::move(rec);
  }

  bool RegisterImage(MapperState& state, image_t image_id, Random& random) {
    Timer timer;
    Reconstruction& rec = state.reconstruction();
    const Image& image = rec.GetImage(image_id);
    std::vector<Eigen::Vector2d> points2D;
    std::vector<Eigen::Vector3d> points3D;
    for (point2D_t idx = 0; idx < image.points2D.size(); ++idx) {
      const int track = state.TrackOf(image_id, idx);
      if (track < 0) continue;
      const point3D_t point = state.PointOfTrack(track);
      if (point == kInvalidPoint3DId) continue;
      points2D.push_back(image.points2D[idx].xy);
      points3D.push_back(rec.GetPoint3D(point).xyz);
    }
    AbsolutePoseEstimationOptions pose_options;
    pose_options.max_error_px = options_.abs_pose_max_error_px;
    pose_options.min_num_inliers = options_.abs_pose_min_num_inliers;
    const AbsolutePoseReport result =
        EstimateAbsolutePose(points2D, points3D, rec.GetCamera(image.camera_id), pose_options, random);
    report_.seconds_registration += timer.ElapsedSeconds();
    if (!result.success || static_cast<int>(result.num_inliers) < options_.abs_pose_min_num_inliers ||
        result.num_inliers < options_.abs_pose_min_inlier_ratio * points2D.size()) {
      spdlog::debug("could not register {}: {} of {} correspondences fit", image.name,
                    result.num_inliers, points2D.size());
      return false;
    }
    rec.GetImage(image_id).cam_from_world = result.cam_from_world;
    rec.RegisterImage(image_id);
    ++report_.num_registered;
    return true;
  }

  void LocalBundle(MapperState& state, image_t image_id) {
    Timer timer;
    Reconstruction& rec = state.reconstruction();
    // The frames sharing most 3D points with the new one.
    std::unordered_map<image_t, size_t> shared;
    std::vector<point3D_t> points;
    for (const Point2D& p : rec.GetImage(image_id).points2D) {
      if (!p.HasPoint3D()) continue;
      points.push_back(p.point3D_id);
      for (const TrackElement& el : rec.GetPoint3D(p.point3D_id).track.elements) {
        if (el.image_id != image_id) ++shared[el.image_id];
      }
    }
    std::vector<std::pair<size_t, image_t>> ranked;
    for (const auto& [id, count] : shared) ranked.push_back({count, id});
    std::sort(ranked.begin(), ranked.end(), std::greater<>());
    BundleAdjustmentConfig config;
    config.AddImage(image_id);
    for (size_t i = 0; i < ranked.size() && i < static_cast<size_t>(options_.local_ba_num_images); ++i) {
      config.AddImage(ranked[i].second);
    }
    FixGauge(config);
    for (const auto& [id, camera] : rec.Cameras()) config.SetConstantCamera(id);
    BundleAdjustmentOptions ba_options = BundleAdjustmentOptions::Local();
    ba_options.num_threads = options_.num_threads > 0 ? options_.num_threads : -1;
    BundleAdjuster adjuster(ba_options, config);
    adjuster.Solve(&rec);
    // Points of the local frames may have moved: check them.
    std::vector<point3D_t> touched;
    for (image_t id : config.ImageIds()) {
      for (const Point2D& p : rec.GetImage(id).points2D) {
        if (p.HasPoint3D()) touched.push_back(p.point3D_id);
      }
    }
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    state.FilterPoints(touched);
    ++report_.num_local_ba;
    report_.seconds_local_ba += timer.ElapsedSeconds();
  }

  void FixGauge(BundleAdjustmentConfig& config) const {
    if (config.HasImage(init1_) && config.HasImage(init2_)) {
      // The config must also have a constant image when all registered frames are in it.
      config.SetConstantPose(init1_);
      config.SetConstantTranslationCoords(init2_, {0});
    } else if (config.HasImage(init1_)) {
      config.SetConstantPose(init1_);
    }
  }

  void GlobalBundle(MapperState& state) {
    Timer timer;
    Reconstruction& rec = state.reconstruction();
    BundleAdjustmentConfig config;
    for (image_t id : rec.RegImageIds()) config.AddImage(id);
    FixGaugeWithTwoImages(rec, init1_, init2_, &config);
    BundleAdjustmentOptions ba_options = BundleAdjustmentOptions::Global();
    ba_options.num_threads = options_.num_threads > 0 ? options_.num_threads : -1;
    bool any_guessed = false;
    for (const auto& [id, camera] : rec.Cameras()) {
      if (camera.has_prior_focal_length || !options_.refine_guessed_focal_length) {
        if (!options_.refine_extra_params) config.SetConstantCamera(id);
      } else {
        any_guessed = true;
      }
    }
    // Focal length is poorly constrained by few frames: refine it once the model has some.
    ba_options.refine_focal_length = any_guessed && rec.NumRegImages() >= 5;
    ba_options.refine_extra_params = options_.refine_extra_params && rec.NumRegImages() >= 10;
    BundleAdjuster adjuster(ba_options, config);
    adjuster.Solve(&rec);
    ++report_.num_global_ba;
    report_.seconds_global_ba += timer.ElapsedSeconds();
  }

  // Global bundle, re-triangulation of all tracks, filtering, and a second bundle when
  // filtering or re-triangulation changed much.
  void GlobalRefinement(MapperState& state) {
    GlobalBundle(state);
    Timer tri_timer;
    const size_t added = state.RetriangulateAll();
    report_.seconds_triangulation += tri_timer.ElapsedSeconds();
    const size_t removed = state.FilterPoints({});
    const size_t observations = state.reconstruction().ComputeNumObservations();
    if (added + removed > 0.02 * observations) {
      GlobalBundle(state);
      state.FilterPoints({});
    }
  }

  const MapperInput& input_;
  const IncrementalMapperOptions& options_;
  MapperReport& report_;
  MapperProgress progress_;
  std::unordered_map<image_t, size_t> frame_index_;
  std::unordered_map<camera_t, Camera> camera_of_id_;
  std::unordered_set<image_t> used_;
  image_t init1_ = kInvalidImageId, init2_ = kInvalidImageId;
};

}  // namespace

std::vector<Reconstruction> RunIncrementalMapper(const MapperInput& input,
                                                 const IncrementalMapperOptions& options,
                                                 MapperReport* report,
                                                 const MapperProgress& progress) {
  options.Check();
  MapperReport local;
  IncrementalMapper mapper(input, options, report ? report : &local, progress);
  return mapper.Run();
}

}  // namespace loopsfm
