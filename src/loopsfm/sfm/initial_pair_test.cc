#include "loopsfm/sfm/initial_pair.h"

#include <gtest/gtest.h>

#include "loopsfm/geometry/triangulation.h"
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

}  // namespace
}  // namespace loopsfm
