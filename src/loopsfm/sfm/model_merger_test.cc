#include "loopsfm/sfm/model_merger.h"

#include <gtest/gtest.h>

#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {

using testing::ComparePoses;
using testing::MakeMapperProblem;
using testing::MapperProblem;
using testing::MapperProblemOptions;

// A model of frames [begin, end) at their true poses moved into another world frame by
// model_from_true (as an independently started model would be).
std::unique_ptr<MapperState> ModelOf(const MapperProblem& p, const IncrementalMapperOptions& options,
                                     int begin, int end, const Sim3d& model_from_true) {
  auto state = std::make_unique<MapperState>(p.input, options);
  for (int i = begin; i < end; ++i) {
    const image_t id = p.input.frames[i].image_id;
    state->reconstruction().GetImage(id).cam_from_world =
        TransformCamFromWorld(p.cam_from_world[i], model_from_true);
    state->reconstruction().RegisterImage(id);
  }
  state->SetGauge(p.input.frames[begin].image_id, p.input.frames[begin + 1].image_id);
  state->RetriangulateAll();
  state->FilterPoints({});
  return state;
}

Sim3d SomeSim3(double scale, double angle, const Eigen::Vector3d& translation) {
  Sim3d s;
  s.scale = scale;
  s.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d(1, 2, 3).normalized()));
  s.translation = translation;
  return s;
}

TEST(ModelMerger, MergesOverlappingModelsThroughTheirCommonTracks) {
  MapperProblemOptions problem_options;
  problem_options.num_frames = 30;
  const MapperProblem p = MakeMapperProblem(problem_options);
  IncrementalMapperOptions options;
  const Sim3d a_from_true = SomeSim3(1.0, 0.0, Eigen::Vector3d::Zero());
  const Sim3d b_from_true = SomeSim3(0.37, 1.1, Eigen::Vector3d(3, -2, 5));
  auto a = ModelOf(p, options, 0, 18, a_from_true);
  auto b = ModelOf(p, options, 14, 30, b_from_true);
  Random random(1);
  const ModelMergeReport report = MergeModels(*a, *b, random);
  ASSERT_TRUE(report.success);
  EXPECT_GT(report.num_inliers, 0.9 * report.num_correspondences);
  // dst_from_src = a_from_true * true_from_b.
  const Sim3d expected = [&] {
    const Sim3d true_from_b = b_from_true.Inverse();
    Sim3d s;
    s.scale = a_from_true.scale * true_from_b.scale;
    s.rotation = a_from_true.rotation * true_from_b.rotation;
    s.translation = a_from_true * true_from_b.translation;
    return s;
  }();
  EXPECT_NEAR(report.dst_from_src.scale / expected.scale, 1.0, 1e-2);
  EXPECT_LT(report.dst_from_src.rotation.angularDistance(expected.rotation), 1e-2);
  EXPECT_EQ(report.num_images_added, 12);
  EXPECT_GT(report.num_points_added + report.num_points_joined, 500);
  EXPECT_EQ(a->reconstruction().NumRegImages(), 30u);
  MapperReport mapper_report;
  a->GlobalRefinement(&mapper_report);
  EXPECT_EQ(mapper_report.num_failed_bundles, 0);
  const auto error = ComparePoses(a->reconstruction(), p);
  EXPECT_EQ(error.num_registered, 30);
  EXPECT_LT(error.max_centre_error, 2e-3);
  EXPECT_LT(error.max_rotation_deg, 0.2);
}

TEST(ModelMerger, RefusesModelsWhoseCommonPointsDisagree) {
  const MapperProblem p = MakeMapperProblem({});
  IncrementalMapperOptions options;
  auto a = ModelOf(p, options, 0, 18, SomeSim3(1, 0, Eigen::Vector3d::Zero()));
  auto b = ModelOf(p, options, 14, 30, SomeSim3(2, 0.5, Eigen::Vector3d(1, 1, 1)));
  // Model b's structure is wrong (as a model grown on repeated facades could be): its
  // points are scattered, so no similarity brings them onto a's.
  Random scatter(9);
  for (auto& [id, point] : b->reconstruction().Points3D()) {
    point.xyz += Eigen::Vector3d(scatter.Normal(0, 2), scatter.Normal(0, 2), scatter.Normal(0, 2));
  }
  const size_t points_before = a->reconstruction().NumPoints3D();
  Random random(2);
  const ModelMergeReport report = MergeModels(*a, *b, random);
  EXPECT_GT(report.num_correspondences, 500);
  EXPECT_FALSE(report.success) << report.num_inliers << " of " << report.num_correspondences;
  EXPECT_EQ(a->reconstruction().NumRegImages(), 18u);
  EXPECT_EQ(a->reconstruction().NumPoints3D(), points_before);
}

}  // namespace
}  // namespace loopsfm
