#include "loopsfm/pipeline/global_mapper_checkpoint.h"

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>

#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {
namespace fs = std::filesystem;

// One global mapping of a 30-frame walk with every checkpoint it hands out, shared by the
// tests.
class GlobalMapperCheckpointTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    testing::MapperProblemOptions problem_options;
    problem_options.num_frames = 30;
    problem_ = testing::MakeMapperProblem(problem_options);
    mapper_options_.num_threads = 1;
    GlobalMapperCheckpointing saving;
    saving.save = [&](const GlobalMapperCheckpoint& c) { checkpoints_.push_back(c); };
    models_ = RunGlobalMapper(problem_.input, mapper_options_, options_, &report_,
                              &mapper_report_, nullptr, saving);
  }
  void SetUp() override {
    ASSERT_EQ(models_.size(), 1u);
    dir_ = fs::temp_directory_path() /
           ("loopsfm_global_ckpt_" +
            std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  nlohmann::json Fingerprint() const {
    return GlobalMapperCheckpointFingerprint(problem_.input, mapper_options_, options_);
  }

  // The models and reports of a run that goes on from `checkpoint`.
  std::vector<Reconstruction> Resume(const GlobalMapperCheckpoint& checkpoint,
                                     GlobalMapperReport* report,
                                     MapperReport* mapper_report) const {
    GlobalMapperCheckpointing resuming;
    resuming.resume = &checkpoint;
    return RunGlobalMapper(problem_.input, mapper_options_, options_, report, mapper_report,
                           nullptr, resuming);
  }

  static void ExpectSameModel(const Reconstruction& a, const Reconstruction& b) {
    ASSERT_EQ(a.RegImageIds(), b.RegImageIds());
    for (const image_t id : a.RegImageIds()) {
      EXPECT_EQ(a.GetImage(id).cam_from_world.rotation.coeffs(),
                b.GetImage(id).cam_from_world.rotation.coeffs());
      EXPECT_EQ(a.GetImage(id).cam_from_world.translation,
                b.GetImage(id).cam_from_world.translation);
    }
    for (const auto& [id, camera] : a.Cameras()) EXPECT_EQ(camera.params, b.GetCamera(id).params);
    ASSERT_EQ(a.Point3DIds(), b.Point3DIds());
    for (const point3D_t id : a.Point3DIds()) {
      ASSERT_EQ(a.GetPoint3D(id).xyz, b.GetPoint3D(id).xyz);
    }
  }

  fs::path dir_;
  static inline testing::MapperProblem problem_;
  static inline IncrementalMapperOptions mapper_options_;
  static inline GlobalMapperOptions options_;
  static inline std::vector<GlobalMapperCheckpoint> checkpoints_;
  static inline std::vector<Reconstruction> models_;
  static inline GlobalMapperReport report_;
  static inline MapperReport mapper_report_;
};

// A checkpoint after the view graph and after each stage of the one component: rotations,
// positions, loose bundles, model.
TEST_F(GlobalMapperCheckpointTest, OneCheckpointAfterEachStage) {
  ASSERT_EQ(checkpoints_.size(), 5u);
  ASSERT_EQ(checkpoints_[0].components.size(), 1u);
  EXPECT_FALSE(checkpoints_[0].components[0].rotations.has_value());
  EXPECT_TRUE(checkpoints_[1].components[0].rotations.has_value());
  EXPECT_FALSE(checkpoints_[1].components[0].positioned.has_value());
  EXPECT_TRUE(checkpoints_[2].components[0].positioned.has_value());
  EXPECT_TRUE(checkpoints_[3].components[0].loose.has_value());
  EXPECT_FALSE(checkpoints_[3].components[0].done);
  EXPECT_TRUE(checkpoints_[4].components[0].done);
  EXPECT_TRUE(checkpoints_[4].components[0].model.has_value());
}

// Written, read back and gone on from, after each stage: the same model, bit for bit, as the
// run that was never stopped, and the same report.
TEST_F(GlobalMapperCheckpointTest, GoingOnFromTheFileGivesTheUninterruptedResult) {
  const fs::path path = dir_ / "global_mapper_checkpoint.bin";
  for (size_t k = 0; k < checkpoints_.size(); ++k) {
    SCOPED_TRACE(k);
    WriteGlobalMapperCheckpoint(path, checkpoints_[k], Fingerprint());
    EXPECT_FALSE(fs::exists(dir_ / "global_mapper_checkpoint.bin.partial"));
    const std::optional<GlobalMapperCheckpoint> read =
        ReadGlobalMapperCheckpoint(path, problem_.input, Fingerprint());
    ASSERT_TRUE(read.has_value());
    GlobalMapperReport report;
    MapperReport mapper_report;
    const std::vector<Reconstruction> resumed = Resume(*read, &report, &mapper_report);
    ASSERT_EQ(resumed.size(), 1u);
    ExpectSameModel(models_[0], resumed[0]);
    EXPECT_EQ(report.num_registered, report_.num_registered);
    EXPECT_EQ(report.num_view_graph_edges, report_.num_view_graph_edges);
    EXPECT_EQ(report.rotations.num_iterations, report_.rotations.num_iterations);
    EXPECT_EQ(report.positioning.num_observations, report_.positioning.num_observations);
    EXPECT_EQ(report.positioning.termination, report_.positioning.termination);
    EXPECT_EQ(mapper_report.num_global_ba, mapper_report_.num_global_ba);
    // Stage times are this run's: none for the stages the checkpoint had done.
    EXPECT_EQ(report.seconds_view_graph, 0.0);
    if (k >= 2) {
      EXPECT_EQ(report.seconds_positioning, 0.0);
    }
  }
}

// Another input or other options: set aside, and mapping starts from the beginning.
TEST_F(GlobalMapperCheckpointTest, OtherInputOrOptionsSetTheCheckpointAside) {
  const fs::path path = dir_ / "global_mapper_checkpoint.bin";
  WriteGlobalMapperCheckpoint(path, checkpoints_[2], Fingerprint());
  GlobalMapperOptions other = options_;
  other.loose_points_per_frame += 1;
  EXPECT_FALSE(ReadGlobalMapperCheckpoint(
                   path, problem_.input,
                   GlobalMapperCheckpointFingerprint(problem_.input, mapper_options_, other))
                   .has_value());
  MapperInput fewer = problem_.input;
  fewer.pairs.pop_back();
  EXPECT_FALSE(ReadGlobalMapperCheckpoint(
                   path, fewer, GlobalMapperCheckpointFingerprint(fewer, mapper_options_, options_))
                   .has_value());
  // No file, or the incremental mapper's.
  EXPECT_FALSE(ReadGlobalMapperCheckpoint(dir_ / "missing.bin", problem_.input, Fingerprint())
                   .has_value());
  const fs::path incremental = dir_ / "mapper_checkpoint.bin";
  std::ofstream(incremental, std::ios::binary) << "loopsfm mapper checkpoint\n\x05";
  EXPECT_FALSE(
      ReadGlobalMapperCheckpoint(incremental, problem_.input, Fingerprint()).has_value());
}

// Every cut and every flipped byte of a checkpoint file: nullopt or a checkpoint, never a
// crash or an exception.
TEST_F(GlobalMapperCheckpointTest, DamagedFilesAreSetAside) {
  const fs::path path = dir_ / "global_mapper_checkpoint.bin";
  WriteGlobalMapperCheckpoint(path, checkpoints_[3], Fingerprint());
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const fs::path damaged = dir_ / "damaged.bin";
  for (size_t cut = 0; cut < bytes.size(); cut += 1 + bytes.size() / 97) {
    std::ofstream(damaged, std::ios::binary | std::ios::trunc) << bytes.substr(0, cut);
    EXPECT_FALSE(ReadGlobalMapperCheckpoint(damaged, problem_.input, Fingerprint()).has_value())
        << cut;
  }
  for (size_t at = 0; at < bytes.size(); at += 1 + bytes.size() / 211) {
    std::string flipped = bytes;
    flipped[at] = static_cast<char>(flipped[at] ^ 0x5a);
    std::ofstream(damaged, std::ios::binary | std::ios::trunc) << flipped;
    EXPECT_NO_THROW(ReadGlobalMapperCheckpoint(damaged, problem_.input, Fingerprint())) << at;
  }
}

// The same mapping again in this process, with the heap in another state: the same bits
// (global positioning's blocks used to be ordered by their addresses in map nodes).
TEST_F(GlobalMapperCheckpointTest, ARunRepeatsItselfInTheSameProcess) {
  std::vector<std::vector<double>> clutter(1000, std::vector<double>(7));
  GlobalMapperReport report;
  MapperReport mapper_report;
  const std::vector<Reconstruction> again =
      RunGlobalMapper(problem_.input, mapper_options_, options_, &report, &mapper_report);
  ASSERT_EQ(again.size(), 1u);
  ExpectSameModel(models_[0], again[0]);
}

}  // namespace
}  // namespace loopsfm
