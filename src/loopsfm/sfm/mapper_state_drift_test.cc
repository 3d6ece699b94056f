// MapperState on a drifted walk out and back (loop_test_problem.h): the alternate-pose
// diagnostic and the bundles that refine a map after a loop correction.

#include <algorithm>
#include <map>
#include <unordered_set>
#include <vector>

#include <gtest/gtest.h>

#include "loopsfm/sfm/loop_test_problem.h"
#include "loopsfm/sfm/mapper_state.h"

namespace loopsfm {
namespace {

using testing::LoopOptions;
using testing::MapperProblem;
using testing::RegisterWithDrift;
using testing::WalkOutAndBack;

// The alternate pose diagnostic: a frame at the end of the drifted walk back sees each
// track's old point (where the first frames put it) and its recent one (where the drifted
// walk back put it); registered again, one pose fits one end and a second RANSAC over the
// rest finds the other, as far away as the drift.
MapperReport RegisterLastFrameAgain(double drift_per_frame) {
  const MapperProblem p = WalkOutAndBack();
  IncrementalMapperOptions options = LoopOptions();
  options.record_alternate_poses = true;
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, drift_per_frame);
  const image_t last = p.input.frames.back().image_id;
  state.reconstruction().DeRegisterImage(last);
  MapperReport report;
  Random random(9);
  EXPECT_TRUE(state.RegisterImage(last, random, &report));
  return report;
}

TEST(AlternatePose, DriftedEndHasTwoPlausiblePoses) {
  const MapperReport report = RegisterLastFrameAgain(0.015);
  ASSERT_EQ(report.registrations.size(), 1u);
  const RegistrationRounds& r = report.registrations[0];
  EXPECT_TRUE(r.second_pose_found) << r.second_num_inliers << " of " << r.second_num_correspondences;
  // The walk back's last frame drifted by 39 x 1.5 cm along (0.3, 1, 0.5): 0.68 m.
  const double drift = 39 * 0.015 * Eigen::Vector3d(0.3, 1.0, 0.5).norm();
  EXPECT_NEAR(r.second_centre_distance, drift, 0.25 * drift);
}

TEST(AlternatePose, ConsistentMapHasOnePose) {
  const MapperReport report = RegisterLastFrameAgain(0.0);
  ASSERT_EQ(report.registrations.size(), 1u);
  EXPECT_FALSE(report.registrations[0].second_pose_found);
  EXPECT_GT(report.registrations[0].num_inliers, 0.9 * report.registrations[0].num_correspondences);
}

// The walk registered at its true poses, then every frame but the two gauge frames moved
// and turned at random, its points left where they were: a map as a pose-graph correction
// leaves it, its cameras far from the bundle's optimum.
void RegisterThenDisturb(const MapperProblem& p, MapperState& state) {
  RegisterWithDrift(p, state, 0.0);
  Random random(21);
  for (size_t i = 2; i < p.input.frames.size(); ++i) {
    Rigid3d& pose = state.reconstruction().GetImage(p.input.frames[i].image_id).cam_from_world;
    const Eigen::Vector3d axis = Eigen::Vector3d(random.Normal(), random.Normal(),
                                                 random.Normal()).normalized();
    pose.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.005, axis)) * pose.rotation;
    pose.translation += 0.03 * Eigen::Vector3d(random.Normal(), random.Normal(),
                                               random.Normal());
  }
}

TEST(MapperState, SubsetBundleTakesTheLongestWellTriangulatedTracksOfEveryFrame) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, 0.0);
  const Reconstruction& rec = state.reconstruction();
  const int per_frame = 40;
  const std::unordered_set<point3D_t> subset = state.LongestTrackPoints(per_frame);
  ASSERT_LT(subset.size(), rec.NumPoints3D() / 2);
  std::map<image_t, int> taken;
  size_t shortest_taken = 1000;
  for (point3D_t id : subset) {
    const Point3D& point = rec.GetPoint3D(id);
    shortest_taken = std::min(shortest_taken, point.track.Length());
    for (const TrackElement& el : point.track.elements) ++taken[el.image_id];
  }
  for (image_t id : rec.RegImageIds()) EXPECT_GE(taken[id], per_frame) << "frame " << id;
  // Longest first: a frame's points left out are no longer than the shortest it took, or
  // the frame had enough already.
  size_t longer_left_out = 0;
  for (const auto& [id, point] : rec.Points3D()) {
    longer_left_out += subset.count(id) == 0 && point.track.Length() > shortest_taken + 2;
  }
  EXPECT_LT(longer_left_out, rec.NumPoints3D() / 2);
}

TEST(MapperState, SubsetBundleDropsObservationsThatNoLongerFitTheMovedCameras) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState state(p.input, options);
  RegisterWithDrift(p, state, 0.0);
  Reconstruction& rec = state.reconstruction();
  const int per_frame = 40;
  const std::unordered_set<point3D_t> subset = state.LongestTrackPoints(per_frame);
  // One observation of each of a few points outside the subset moved 40 px: the subset
  // bundle re-triangulates those points from the cameras, and these observations do not fit.
  std::vector<TrackElement> moved;
  std::vector<point3D_t> ids;
  for (const auto& [id, point] : rec.Points3D()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  for (const point3D_t id : ids) {
    const Point3D& point = rec.GetPoint3D(id);
    if (subset.count(id) > 0 || point.track.Length() < 5) continue;
    moved.push_back(point.track.elements[1]);
    if (moved.size() == 10) break;
  }
  ASSERT_EQ(moved.size(), 10u);
  for (const TrackElement& el : moved) {
    rec.GetImage(el.image_id).points2D[el.point2D_idx].xy += Eigen::Vector2d(40.0, 0.0);
  }
  MapperReport report;
  state.SubsetBundle(&report, per_frame);
  for (const TrackElement& el : moved) {
    EXPECT_FALSE(rec.GetImage(el.image_id).points2D[el.point2D_idx].HasPoint3D())
        << "frame " << el.image_id << " observation " << el.point2D_idx;
  }
}

TEST(MapperState, SubsetBundleEndsAtTheFunctionToleranceItIsGiven) {
  const MapperProblem p = WalkOutAndBack();
  const IncrementalMapperOptions options = LoopOptions();
  MapperState loose(p.input, options), tight(p.input, options);
  RegisterThenDisturb(p, loose);
  RegisterThenDisturb(p, tight);
  MapperReport loose_report, tight_report;
  loose.SubsetBundle(&loose_report, 40, {}, {}, 1e-2);
  tight.SubsetBundle(&tight_report, 40, {}, {}, 1e-10);
  ASSERT_EQ(loose_report.num_global_ba, 1);
  ASSERT_EQ(tight_report.num_global_ba, 1);
  EXPECT_LT(loose_report.num_global_ba_iterations, tight_report.num_global_ba_iterations);
}

TEST(MapperState, RefinementAfterACorrectionEndsWhereTheFullBundleDoes) {
  const MapperProblem p = WalkOutAndBack();
  IncrementalMapperOptions options = LoopOptions();
  options.loop_closure.refine_points_per_frame = 40;
  MapperState full(p.input, options), subset(p.input, options);
  RegisterThenDisturb(p, full);
  RegisterThenDisturb(p, subset);
  const testing::PoseError disturbed = testing::ComparePoses(full.reconstruction(), p);
  MapperReport full_report, subset_report;
  full.GlobalRefinement(&full_report);
  subset.RefineAfterCorrection(&subset_report, options.loop_closure.refine_function_tolerance);
  EXPECT_EQ(subset_report.num_global_ba, full_report.num_global_ba + 1);
  const testing::PoseError after_full = testing::ComparePoses(full.reconstruction(), p);
  const testing::PoseError after_subset = testing::ComparePoses(subset.reconstruction(), p);
  EXPECT_LT(after_full.max_centre_error, 0.1 * disturbed.max_centre_error);
  EXPECT_LT(after_subset.max_centre_error, 0.1 * disturbed.max_centre_error);
  // As close to the truth as the full bundle's answer (the same up to the solvers' ends).
  EXPECT_NEAR(after_subset.max_centre_error, after_full.max_centre_error,
              0.05 * after_full.max_centre_error);
  EXPECT_NEAR(after_subset.max_rotation_deg, after_full.max_rotation_deg,
              0.05 * after_full.max_rotation_deg + 1e-3);
}

}  // namespace
}  // namespace loopsfm
