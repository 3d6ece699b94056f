#include "loopsfm/sfm/initial_pair.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "loopsfm/geometry/triangulation.h"
#include "loopsfm/math/random.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {

using testing::MakeMapperProblem;
using testing::MapperProblem;

int FrameIndex(const MapperProblem& p, image_t id) {
  for (size_t i = 0; i < p.input.frames.size(); ++i) {
    if (p.input.frames[i].image_id == id) return static_cast<int>(i);
  }
  return -1;
}

TEST(InitialPair, RanksByWellConditionedInliers) {
  const MapperProblem p = MakeMapperProblem({});
  IncrementalMapperOptions options;
  const auto candidates = RankInitialPairs(p.input, options);
  ASSERT_FALSE(candidates.empty());
  // Sorted by tier, then by well-conditioned inliers.
  for (size_t c = 1; c < candidates.size(); ++c) {
    const auto& a = candidates[c - 1];
    const auto& b = candidates[c];
    EXPECT_TRUE(a.tier < b.tier || (a.tier == b.tier && a.num_well_conditioned >= b.num_well_conditioned));
  }
  const InitialPairCandidate& best = candidates.front();
  EXPECT_EQ(best.tier, 0);
  // Neighbouring frames (0.3 m apart, 8-12 m from the wall: under 2.2 degrees) have the
  // most inliers but none well conditioned: they are never candidates.
  const int i = FrameIndex(p, best.pair->pair.image_id1), j = FrameIndex(p, best.pair->pair.image_id2);
  EXPECT_GE(std::abs(i - j), 3);
  for (const auto& c : candidates) {
    const int a = FrameIndex(p, c.pair->pair.image_id1), b = FrameIndex(p, c.pair->pair.image_id2);
    EXPECT_GT(std::abs(a - b), 1) << "neighbours are never candidates";
  }
  // The count agrees with the true triangulation angles (noise moves a few across 3 deg).
  int truth = 0;
  const Eigen::Vector3d ci = p.cam_from_world[i].Inverse().translation;
  const Eigen::Vector3d cj = p.cam_from_world[j].Inverse().translation;
  for (const FeatureMatch& m : best.pair->geometry.inlier_matches) {
    const int point = p.keypoint_point[i < j ? i : j][m.point2D_idx1];
    truth += CalculateTriangulationAngle(ci, cj, p.points[point]) >= 3.0 * M_PI / 180.0;
  }
  EXPECT_NEAR(best.num_well_conditioned, truth, 0.03 * truth);
  EXPECT_GT(best.median_tri_angle_deg, 3.0);
}

TEST(InitialPair, TwoViewModelIsValidatedBeforeGrowing) {
  const MapperProblem p = MakeMapperProblem({});
  IncrementalMapperOptions options;
  const auto candidates = RankInitialPairs(p.input, options);
  ASSERT_FALSE(candidates.empty());
  MapperReport report;
  {
    MapperState state(p.input, options);
    ASSERT_TRUE(InitializeModel(state, candidates.front(), &report));
    EXPECT_GE(static_cast<int>(state.reconstruction().NumPoints3D()), options.init_min_num_points);
    EXPECT_EQ(state.reconstruction().NumRegImages(), 2u);
  }
  // The same pair with only 40 of its matches: a relaxed candidate, and too few points.
  MapperPair weak = *candidates.front().pair;
  weak.geometry.inlier_matches.resize(40);
  InitialPairCandidate candidate = candidates.front();
  candidate.pair = &weak;
  candidate.tier = 1;
  MapperProblem weak_problem = p;
  weak_problem.input.pairs = {weak};
  testing::RebuildTracks(&weak_problem.input);
  candidate.pair = &weak_problem.input.pairs.front();
  MapperState state(weak_problem.input, options);
  EXPECT_FALSE(InitializeModel(state, candidate, &report));
  EXPECT_EQ(report.num_init_trials, 2);
  EXPECT_EQ(report.num_init_accepted, 1);
}

// Two views of 200 points, the second camera turned 8 degrees about the vertical and moved
// by `move`; the points at depth 6..10 m, or all on the plane z = 8 m; 0.3 px noise.
// Returned with a tier-2 candidate (the homography explains both) whose pair the caller sets.
struct TwoViews {
  MapperInput input;
  InitialPairCandidate candidate;
};

TwoViews MakeTwoViews(const Eigen::Vector3d& move, bool planar) {
  TwoViews views;
  const Camera camera = testing::TestCamera();  // 640 x 480, focal 500
  views.input.cameras = {camera};
  const Eigen::Matrix3d turn =
      Eigen::AngleAxisd(8.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Random random(5);
  MapperFrame f1{.image_id = 1, .camera_id = 1, .name = "a.png", .points2D = {}};
  MapperFrame f2{.image_id = 2, .camera_id = 1, .name = "b.png", .points2D = {}};
  MapperPair pair;
  pair.pair = ImagePair(1, 2);
  pair.geometry.config = TwoViewGeometry::kCalibrated;
  while (f1.points2D.size() < 200) {
    const double depth = planar ? 8.0 : random.UniformReal(6.0, 10.0);
    const Eigen::Vector3d x(random.UniformReal(-4.0, 4.0), random.UniformReal(-3.0, 3.0), depth);
    const Eigen::Vector3d in2 = turn * (x - move);
    const Eigen::Vector2d p1 = camera.ImgFromCam(x), p2 = camera.ImgFromCam(in2);
    if (in2.z() <= 0 || p2.x() < 0 || p2.x() > 640 || p2.y() < 0 || p2.y() > 480) continue;
    const Eigen::Vector2d noise1(random.Normal(0, 0.3), random.Normal(0, 0.3));
    const Eigen::Vector2d noise2(random.Normal(0, 0.3), random.Normal(0, 0.3));
    const point2D_t idx = static_cast<point2D_t>(f1.points2D.size());
    f1.points2D.push_back(p1 + noise1);
    f2.points2D.push_back(p2 + noise2);
    pair.geometry.inlier_matches.push_back({idx, idx});
  }
  views.input.frames = {f1, f2};
  views.input.pairs = {pair};
  views.candidate.num_inliers = 200;
  views.candidate.tier = 2;
  return views;
}

TEST(InitialPair, ACameraTurningOnTheSpotIsNeverTried) {
  const IncrementalMapperOptions options;
  // Turned only: a rotation explains every inlier.
  TwoViews turned = MakeTwoViews(Eigen::Vector3d::Zero(), /*planar=*/false);
  turned.candidate.pair = &turned.input.pairs.front();
  EXPECT_TRUE(TurnsOnTheSpot(turned.candidate, turned.input, options));
  // A wall approached by 1 m: the homography explains it, a rotation does not. (Moved
  // sideways instead, a wall ahead looks much like a turn, the panoramic ambiguity.)
  TwoViews wall = MakeTwoViews(Eigen::Vector3d(0.2, 0.0, 1.0), /*planar=*/true);
  wall.candidate.pair = &wall.input.pairs.front();
  EXPECT_FALSE(TurnsOnTheSpot(wall.candidate, wall.input, options));
  // Only planar candidates are asked.
  turned.candidate.tier = 1;
  EXPECT_FALSE(TurnsOnTheSpot(turned.candidate, turned.input, options));
}

}  // namespace
}  // namespace loopsfm
