#include "loopsfm/sfm/global_view_graph.h"

#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <unordered_map>
#include <utility>

#include "loopsfm/matching/geometric_verification.h"

namespace loopsfm {

namespace {

bool HasRelativePose(const TwoViewGeometry& geometry) {
  switch (geometry.config) {
    case TwoViewGeometry::kCalibrated:
    case TwoViewGeometry::kUncalibrated:
    case TwoViewGeometry::kPlanar:
    case TwoViewGeometry::kPanoramic: return true;
    default: return false;
  }
}

// The view graph's edges with their candidate poses (one, or a planar pair's two: F's
// first), and the triangle vote between a planar pair's two.
class CandidateGraph {
 public:
  void Add(image_t id1, image_t id2, std::vector<Rigid3d> candidates) {
    edge_of_[{id1, id2}] = candidates_.size();
    neighbours_[id1].insert(id2);
    neighbours_[id2].insert(id1);
    candidates_.push_back(std::move(candidates));
  }

  const std::vector<Rigid3d>& Candidates(size_t e) const { return candidates_[e]; }

  // The index of the candidate of edge e = (id1, id2) that more triangles agree with (the
  // first on a tie): a triangle (id1, k, id2) agrees when some candidates of its other two
  // edges chain into a rotation within max_angle of the candidate's.
  size_t Vote(size_t e, image_t id1, image_t id2, double max_angle) const {
    std::vector<int> agreeing(candidates_[e].size(), 0);
    const std::set<image_t>& others = neighbours_.at(id2);
    for (const image_t k : neighbours_.at(id1)) {
      if (k == id2 || others.count(k) == 0) continue;
      const std::vector<Eigen::Quaterniond> first = Rotations(id1, k), second = Rotations(k, id2);
      for (size_t c = 0; c < candidates_[e].size(); ++c) {
        const Eigen::Quaterniond& rotation = candidates_[e][c].rotation;
        bool agrees = false;
        for (const Eigen::Quaterniond& a : first) {
          for (const Eigen::Quaterniond& b : second) {
            agrees = agrees || (b * a).angularDistance(rotation) <= max_angle;
          }
        }
        agreeing[c] += agrees ? 1 : 0;
      }
    }
    size_t best = 0;
    for (size_t c = 1; c < agreeing.size(); ++c) {
      if (agreeing[c] > agreeing[best]) best = c;
    }
    return best;
  }

 private:
  // The candidate rotations cam_to_from_cam_from of the edge between the two frames.
  std::vector<Eigen::Quaterniond> Rotations(image_t from, image_t to) const {
    std::vector<Eigen::Quaterniond> rotations;
    if (const auto forward = edge_of_.find({from, to}); forward != edge_of_.end()) {
      for (const Rigid3d& pose : candidates_[forward->second]) rotations.push_back(pose.rotation);
    } else if (const auto backward = edge_of_.find({to, from}); backward != edge_of_.end()) {
      for (const Rigid3d& pose : candidates_[backward->second]) {
        rotations.push_back(pose.rotation.conjugate());
      }
    }
    return rotations;
  }

  std::map<std::pair<image_t, image_t>, size_t> edge_of_;
  std::unordered_map<image_t, std::set<image_t>> neighbours_;
  std::vector<std::vector<Rigid3d>> candidates_;
};

}  // namespace

FrameLookup::FrameLookup(const MapperInput& input) {
  for (const MapperFrame& frame : input.frames) {
    capture_index_[frame.image_id] = static_cast<int>(frames_.size());
    frames_[frame.image_id] = &frame;
  }
  for (const Camera& camera : input.cameras) cameras_[camera.camera_id] = &camera;
}

std::vector<PairPose> PairPoses(const MapperInput& input, const FrameLookup& lookup,
                                const GlobalMapperOptions& options, GlobalMapperReport* report) {
  report->num_planar_pairs = report->num_planar_poses_from_homography = 0;
  std::vector<PairPose> poses;
  CandidateGraph graph;
  for (const MapperPair& pair : input.pairs) {
    const TwoViewGeometry& geometry = pair.geometry;
    if (!geometry.IsVerified() || !HasRelativePose(geometry)) continue;
    const image_t id1 = pair.pair.image_id1, id2 = pair.pair.image_id2;
    std::vector<Rigid3d> candidates{geometry.cam2_from_cam1};
    if (geometry.config == TwoViewGeometry::kPlanar) {
      const std::optional<Rigid3d> essential = EssentialPoseOfPair(
          lookup.CameraOf(id1), lookup.Frame(id1).points2D, lookup.CameraOf(id2),
          lookup.Frame(id2).points2D, options.verification, geometry);
      if (essential) {
        ++report->num_planar_pairs;
        candidates.insert(candidates.begin(), *essential);
        if (!options.planar_pose_by_triangles) candidates.resize(1);
      }
    }
    poses.push_back({id1, id2, candidates.front(),
                     geometry.config != TwoViewGeometry::kPanoramic,
                     static_cast<double>(geometry.inlier_matches.size())});
    graph.Add(id1, id2, std::move(candidates));
  }
  const double max_angle = options.view_graph.max_loop_error_deg * M_PI / 180.0;
  for (size_t e = 0; e < poses.size(); ++e) {
    PairPose& pose = poses[e];
    if (graph.Candidates(e).size() > 1) {
      const size_t chosen = graph.Vote(e, pose.image_id1, pose.image_id2, max_angle);
      pose.cam2_from_cam1 = graph.Candidates(e)[chosen];
      report->num_planar_poses_from_homography += chosen == 1 ? 1 : 0;
    }
    pose.has_translation = pose.has_translation && pose.cam2_from_cam1.translation.norm() > 0.0;
  }
  return poses;
}

std::vector<int> RunsBetweenCuts(const MapperInput& input) {
  std::set<std::pair<image_t, image_t>> paired;
  for (const MapperPair& pair : input.pairs) {
    if (!pair.geometry.IsVerified()) continue;
    paired.insert(std::minmax(pair.pair.image_id1, pair.pair.image_id2));
  }
  std::vector<int> run(input.frames.size(), 0);
  for (size_t k = 1; k < input.frames.size(); ++k) {
    const bool cut =
        paired.count(std::minmax(input.frames[k - 1].image_id, input.frames[k].image_id)) == 0;
    run[k] = run[k - 1] + (cut ? 1 : 0);
  }
  return run;
}

}  // namespace loopsfm
