#include "loopsfm/sfm/initial_pair.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include <Eigen/SVD>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm {
namespace {

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

// Fraction of a pair's inliers that a pure rotation of the camera (no baseline) maps within
// max_error pixels, at the best of focal lengths from half to twice the camera's (the focal
// length may still be a guess). For each, the rotation that best aligns the inliers' viewing
// rays (Kabsch), fitted again to those it maps within 8x, then 2x the threshold (a wrong match
// among the inliers skews the first fit). Near 1 for a camera turning on the spot, where the
// homography's decomposition under a wrong focal length finds a spurious translation and
// triangulation angles of several degrees; low for a baseline seen in depth or in a plane's
// perspective.
double RotationInlierRatio(const MapperPair& pair, const Camera& c1, const Camera& c2,
                           const MapperFrame& f1, const MapperFrame& f2, double max_error) {
  const auto& inliers = pair.geometry.inlier_matches;
  if (inliers.empty()) return 0.0;
  std::vector<Eigen::Vector2d> xs1, xs2;  // normalised image points
  for (const FeatureMatch& m : inliers) {
    xs1.push_back(c1.CamFromImg(f1.points2D[m.point2D_idx1]));
    xs2.push_back(c2.CamFromImg(f2.points2D[m.point2D_idx2]));
  }
  const double threshold = max_error / (0.5 * (c1.MeanFocalLength() + c2.MeanFocalLength()));
  constexpr int kSteps = 24;  // focal lengths 6 % apart
  size_t best = 0;
  for (int step = 0; step <= kSteps; ++step) {
    const double scale = std::pow(2.0, -1.0 + 2.0 * step / kSteps);  // trial focal / focal
    auto ray = [&](const Eigen::Vector2d& x) {
      return Eigen::Vector3d((x / scale).homogeneous().normalized());
    };
    std::vector<char> used(xs1.size(), 1);
    size_t count = 0;
    for (const double factor : {8.0, 2.0, 1.0}) {
      Eigen::Matrix3d correlation = Eigen::Matrix3d::Zero();
      for (size_t i = 0; i < xs1.size(); ++i) {
        if (used[i]) correlation += ray(xs2[i]) * ray(xs1[i]).transpose();
      }
      const Eigen::JacobiSVD<Eigen::Matrix3d> svd(correlation,
                                                  Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d sign = Eigen::Matrix3d::Identity();
      sign(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
      const Eigen::Matrix3d cam2_from_cam1 = svd.matrixU() * sign * svd.matrixV().transpose();
      count = 0;
      for (size_t i = 0; i < xs1.size(); ++i) {
        const Eigen::Vector3d in_cam2 = cam2_from_cam1 * ray(xs1[i]);
        used[i] = in_cam2.z() > 1e-12 &&
                  (scale * in_cam2.hnormalized() - xs2[i]).norm() <= factor * threshold;
        count += used[i];
      }
    }
    best = std::max(best, count);
  }
  return double(best) / inliers.size();
}

struct AngleStats {
  int num_well_conditioned = 0;
  double median_deg = 0.0;
};

// Ray angles of the inliers under the pair's relative pose. For rays that meet, the angle
// between them is the triangulation angle; the midpoint depths along both rays must be
// positive.
AngleStats InlierAngles(const MapperPair& pair, const Camera& c1, const Camera& c2,
                        const MapperFrame& f1, const MapperFrame& f2, double min_angle_deg) {
  const Rigid3d& cam2_from_cam1 = pair.geometry.cam2_from_cam1;
  const Eigen::Matrix3d cam1_from_cam2 = cam2_from_cam1.rotation.inverse().toRotationMatrix();
  // Centre of camera 2 in camera 1's frame.
  const Eigen::Vector3d baseline = -(cam1_from_cam2 * cam2_from_cam1.translation);
  if (baseline.squaredNorm() < 1e-24) return {};
  const double cos_min = std::cos(min_angle_deg * M_PI / 180.0);
  std::vector<double> cosines;
  cosines.reserve(pair.geometry.inlier_matches.size());
  AngleStats stats;
  for (const FeatureMatch& m : pair.geometry.inlier_matches) {
    const Eigen::Vector3d r1 = c1.CamFromImg(f1.points2D[m.point2D_idx1]).homogeneous().normalized();
    const Eigen::Vector3d r2 =
        cam1_from_cam2 * c2.CamFromImg(f2.points2D[m.point2D_idx2]).homogeneous().normalized();
    // Midpoint: d1 r1 - d2 r2 = baseline in least squares.
    const double a = r1.dot(r2);
    const double det = 1.0 - a * a;
    const double cosine = a;
    cosines.push_back(cosine);
    if (det < 1e-12) continue;
    const double b1 = r1.dot(baseline), b2 = r2.dot(baseline);
    const double d1 = (b1 - a * b2) / det;
    const double d2 = (a * b1 - b2) / det;
    if (d1 > 0 && d2 > 0 && cosine <= cos_min) ++stats.num_well_conditioned;
  }
  if (cosines.empty()) return stats;
  const size_t mid = cosines.size() / 2;
  std::nth_element(cosines.begin(), cosines.begin() + mid, cosines.end());
  stats.median_deg = std::acos(std::clamp(cosines[mid], -1.0, 1.0)) * 180.0 / M_PI;
  return stats;
}

bool HasRelativePose(const TwoViewGeometry& g) {
  return g.config == TwoViewGeometry::kCalibrated || g.config == TwoViewGeometry::kUncalibrated ||
         g.config == TwoViewGeometry::kPlanar;
}

}  // namespace

std::vector<InitialPairCandidate> RankInitialPairs(const MapperInput& input,
                                                   const IncrementalMapperOptions& options) {
  std::unordered_map<image_t, size_t> frame_index;
  for (size_t i = 0; i < input.frames.size(); ++i) frame_index[input.frames[i].image_id] = i;
  std::unordered_map<camera_t, const Camera*> camera_of_id;
  for (const Camera& camera : input.cameras) camera_of_id[camera.camera_id] = &camera;

  const int relaxed_inliers = options.init_min_num_inliers / 2;
  const int relaxed_points = options.init_min_num_points / 2;
  std::vector<InitialPairCandidate> candidates;
  for (const MapperPair& pair : input.pairs) {
    const TwoViewGeometry& g = pair.geometry;
    const int num_inliers = static_cast<int>(g.inlier_matches.size());
    if (num_inliers < relaxed_inliers || !HasRelativePose(g)) continue;
    const MapperFrame& f1 = input.frames[frame_index.at(pair.pair.image_id1)];
    const MapperFrame& f2 = input.frames[frame_index.at(pair.pair.image_id2)];
    const AngleStats angles = InlierAngles(pair, *camera_of_id.at(f1.camera_id),
                                           *camera_of_id.at(f2.camera_id), f1, f2,
                                           options.init_min_tri_angle_deg);
    if (angles.num_well_conditioned < relaxed_points) continue;
    InitialPairCandidate c;
    c.pair = &pair;
    c.num_inliers = num_inliers;
    c.num_well_conditioned = angles.num_well_conditioned;
    c.median_tri_angle_deg = angles.median_deg;
    c.h_ratio = HomographyInlierRatio(pair, f1, f2, options.max_reproj_error_px);
    if (c.h_ratio > options.init_max_h_inlier_ratio) {
      c.tier = 2;  // planar, or the camera only turned (TurnsOnTheSpot)
    } else if (num_inliers >= options.init_min_num_inliers &&
               angles.num_well_conditioned >= options.init_min_num_points) {
      c.tier = 0;
    } else {
      c.tier = 1;
    }
    candidates.push_back(c);
  }
  std::sort(candidates.begin(), candidates.end(), [&](const auto& a, const auto& b) {
    if (a.tier != b.tier) return a.tier < b.tier;
    if (a.num_well_conditioned != b.num_well_conditioned) {
      return a.num_well_conditioned > b.num_well_conditioned;
    }
    const size_t a1 = frame_index.at(a.pair->pair.image_id1), b1 = frame_index.at(b.pair->pair.image_id1);
    if (a1 != b1) return a1 < b1;
    return frame_index.at(a.pair->pair.image_id2) < frame_index.at(b.pair->pair.image_id2);
  });
  return candidates;
}

bool TurnsOnTheSpot(const InitialPairCandidate& candidate, const MapperInput& input,
                    const IncrementalMapperOptions& options) {
  if (candidate.tier < 2) return false;
  const MapperPair& pair = *candidate.pair;
  auto frame = [&](image_t id) -> const MapperFrame& {
    return *std::find_if(input.frames.begin(), input.frames.end(),
                         [&](const MapperFrame& f) { return f.image_id == id; });
  };
  auto camera = [&](camera_t id) -> const Camera& {
    return *std::find_if(input.cameras.begin(), input.cameras.end(),
                         [&](const Camera& c) { return c.camera_id == id; });
  };
  const MapperFrame& f1 = frame(pair.pair.image_id1);
  const MapperFrame& f2 = frame(pair.pair.image_id2);
  return RotationInlierRatio(pair, camera(f1.camera_id), camera(f2.camera_id), f1, f2,
                             options.max_reproj_error_px) > options.init_max_h_inlier_ratio;
}

bool InitializeModel(MapperState& state, const InitialPairCandidate& candidate,
                     MapperReport* report) {
  Reconstruction& rec = state.reconstruction();
  LOOPSFM_CHECK(rec.NumRegImages() == 0);
  const image_t id1 = candidate.pair->pair.image_id1, id2 = candidate.pair->pair.image_id2;
  rec.GetImage(id1).cam_from_world = Rigid3d();
  rec.GetImage(id2).cam_from_world = candidate.pair->geometry.cam2_from_cam1;
  rec.RegisterImage(id1);
  rec.RegisterImage(id2);
  state.SetGauge(id1, id2);
  state.TriangulateImage(id2);
  state.GlobalBundle(report);
  state.FilterPoints({});
  ++report->num_init_trials;
  const int needed = candidate.tier == 0 ? state.options().init_min_num_points
                                         : state.options().init_min_num_points / 2;
  const bool valid = static_cast<int>(rec.NumPoints3D()) >= needed;
  spdlog::debug("initial pair {} + {} (tier {}, {} inliers, {} well conditioned, median {:.1f} deg, "
                "homography ratio {:.2f}): {} points, {}",
                rec.GetImage(id1).name, rec.GetImage(id2).name, candidate.tier, candidate.num_inliers,
                candidate.num_well_conditioned, candidate.median_tri_angle_deg, candidate.h_ratio,
                rec.NumPoints3D(), valid ? "accepted" : "rejected");
  report->num_init_accepted += valid;
  return valid;
}

}  // namespace loopsfm
