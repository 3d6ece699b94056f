#include "loopsfm/pipeline/mapper_checkpoint.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>

#include "loopsfm/loop/loop_closing.h"
#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {
namespace fs = std::filesystem;

// One mapping of a 20-frame walk, with a checkpoint before every registration, shared by
// the tests.
class MapperCheckpointFileTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    testing::MapperProblemOptions problem_options;
    problem_options.num_frames = 20;
    problem_ = testing::MakeMapperProblem(problem_options);
    options_.num_threads = 1;
    MapperCheckpointing saving;
    saving.interval_seconds = 0.0;
    saving.save = [&](const MapperCheckpoint& c) { checkpoints_.push_back(c); };
    models_ = MapWithLoopClosing(problem_.input, options_, &report_, {}, saving);
  }
  void SetUp() override {
    ASSERT_GT(checkpoints_.size(), 10u);
    dir_ = fs::temp_directory_path() /
           ("loopsfm_ckpt_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string ReadBytes(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  void WriteBytes(const fs::path& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  }

  fs::path dir_;
  static inline testing::MapperProblem problem_;
  static inline IncrementalMapperOptions options_;
  static inline std::vector<MapperCheckpoint> checkpoints_;
  static inline std::vector<Reconstruction> models_;
  static inline MapperReport report_;
};

// Written, read back and resumed from: the same models, bit for bit, as the run that was
// never interrupted, and the same report counts.
TEST_F(MapperCheckpointFileTest, ResumingFromTheFileGivesTheUninterruptedResult) {
  const nlohmann::json fingerprint = MapperCheckpointFingerprint(problem_.input, options_);
  const fs::path path = dir_ / "mapper_checkpoint.bin";
  const MapperCheckpoint& saved = checkpoints_[checkpoints_.size() / 2];
  ASSERT_TRUE(saved.growing.has_value());
  WriteMapperCheckpoint(path, saved, fingerprint);
  EXPECT_FALSE(fs::exists(dir_ / "mapper_checkpoint.bin.partial"));
  const std::optional<MapperCheckpoint> read = ReadMapperCheckpoint(path, fingerprint);
  ASSERT_TRUE(read.has_value());
  EXPECT_EQ(read->NumRegistered(), saved.NumRegistered());
  EXPECT_EQ(read->random_state, saved.random_state);
  EXPECT_EQ(read->tried_initial_pairs, saved.tried_initial_pairs);
  EXPECT_EQ(read->last_global_size, saved.last_global_size);
  EXPECT_FALSE(saved.recent_frames.empty());
  EXPECT_EQ(read->recent_frames, saved.recent_frames);
  EXPECT_EQ(read->report.num_local_ba, saved.report.num_local_ba);
  EXPECT_EQ(read->report.seconds_local_ba, saved.report.seconds_local_ba);

  // Loop links made before the checkpoint are part of its report.
  MapperCheckpoint with_links = saved;
  with_links.report.loop_links = {{"posegraph", "a.png", "b.png", 12}};
  const fs::path links_path = dir_ / "mapper_checkpoint_links.bin";
  WriteMapperCheckpoint(links_path, with_links, fingerprint);
  const std::optional<MapperCheckpoint> read_links = ReadMapperCheckpoint(links_path, fingerprint);
  ASSERT_TRUE(read_links.has_value());
  ASSERT_EQ(read_links->report.loop_links.size(), 1u);
  EXPECT_EQ(read_links->report.loop_links[0].recent_frame, "b.png");
  EXPECT_EQ(read_links->report.loop_links[0].num_point_pairs, 12);

  MapperCheckpointing resuming;
  resuming.resume = &*read;
  MapperReport report;
  const std::vector<Reconstruction> resumed =
      MapWithLoopClosing(problem_.input, options_, &report, {}, resuming);
  ASSERT_EQ(resumed.size(), models_.size());
  const Reconstruction& a = models_[0];
  const Reconstruction& b = resumed[0];
  ASSERT_EQ(a.RegImageIds(), b.RegImageIds());
  for (const image_t id : a.RegImageIds()) {
    EXPECT_EQ(a.GetImage(id).cam_from_world.rotation.coeffs(),
              b.GetImage(id).cam_from_world.rotation.coeffs());
    EXPECT_EQ(a.GetImage(id).cam_from_world.translation, b.GetImage(id).cam_from_world.translation);
  }
  ASSERT_EQ(a.Point3DIds(), b.Point3DIds());
  for (const point3D_t id : a.Point3DIds()) ASSERT_EQ(a.GetPoint3D(id).xyz, b.GetPoint3D(id).xyz);
  EXPECT_EQ(report.num_registered, report_.num_registered);
  EXPECT_EQ(report.num_global_ba, report_.num_global_ba);
}

// Another input or other options: set aside, not used.
TEST_F(MapperCheckpointFileTest, OtherInputOrOptionsSetTheCheckpointAside) {
  const nlohmann::json fingerprint = MapperCheckpointFingerprint(problem_.input, options_);
  const fs::path path = dir_ / "mapper_checkpoint.bin";
  WriteMapperCheckpoint(path, checkpoints_[5], fingerprint);
  ASSERT_TRUE(ReadMapperCheckpoint(path, fingerprint).has_value());

  IncrementalMapperOptions other_options = options_;
  other_options.loop_closure.method = LoopClosingMethod::kSplit;
  EXPECT_FALSE(ReadMapperCheckpoint(path, MapperCheckpointFingerprint(problem_.input, other_options)));
  for (int* window : {&other_options.registration_capture_window,
                      &other_options.registration_neighbour_window}) {
    other_options = options_;
    *window = 0;
    EXPECT_FALSE(
        ReadMapperCheckpoint(path, MapperCheckpointFingerprint(problem_.input, other_options)));
  }
  // The thread count changes only rounding: the checkpoint stays usable.
  other_options = options_;
  other_options.num_threads = 4;
  EXPECT_TRUE(ReadMapperCheckpoint(path, MapperCheckpointFingerprint(problem_.input, other_options)));

  MapperInput other_input = problem_.input;
  other_input.pairs.pop_back();
  EXPECT_FALSE(ReadMapperCheckpoint(path, MapperCheckpointFingerprint(other_input, options_)));
  other_input = problem_.input;
  other_input.cameras[0].params[0] += 1e-9;
  EXPECT_FALSE(ReadMapperCheckpoint(path, MapperCheckpointFingerprint(other_input, options_)));
}

// A damaged file (cut short, a byte changed, garbage, empty) is set aside without an
// exception: a checkpoint only saves time.
TEST_F(MapperCheckpointFileTest, DamagedFilesAreSetAside) {
  const nlohmann::json fingerprint = MapperCheckpointFingerprint(problem_.input, options_);
  const fs::path path = dir_ / "mapper_checkpoint.bin";
  WriteMapperCheckpoint(path, checkpoints_[checkpoints_.size() / 2], fingerprint);
  const std::string bytes = ReadBytes(path);
  ASSERT_GT(bytes.size(), 1000u);
  EXPECT_FALSE(ReadMapperCheckpoint(dir_ / "missing.bin", fingerprint));
  for (const size_t cut : {size_t{0}, size_t{10}, size_t{40}, bytes.size() / 2, bytes.size() - 1}) {
    WriteBytes(path, bytes.substr(0, cut));
    EXPECT_FALSE(ReadMapperCheckpoint(path, fingerprint)) << "cut at " << cut;
  }
  WriteBytes(path, bytes + "x");
  EXPECT_FALSE(ReadMapperCheckpoint(path, fingerprint)) << "a byte too many";
  // The header's length (after the 26-byte magic and the version) claims 2^64 - 1 bytes.
  std::string huge = bytes;
  for (size_t k = 30; k < 38; ++k) huge[k] = '\xff';
  WriteBytes(path, huge);
  EXPECT_FALSE(ReadMapperCheckpoint(path, fingerprint)) << "huge count";
  WriteBytes(path, std::string(5000, '\x7f'));
  EXPECT_FALSE(ReadMapperCheckpoint(path, fingerprint)) << "garbage";
}

// A whole number of the header out of its field's range or not whole is set aside (a float
// past an int's range was undefined behaviour in nlohmann's conversion; an integer past it
// wrapped; fuzz findings).
TEST_F(MapperCheckpointFileTest, HeaderNumbersOutOfRangeAreSetAside) {
  const nlohmann::json fingerprint = MapperCheckpointFingerprint(problem_.input, options_);
  const fs::path path = dir_ / "mapper_checkpoint.bin";
  WriteMapperCheckpoint(path, checkpoints_[checkpoints_.size() / 2], fingerprint);
  const std::string bytes = ReadBytes(path);
  // The header's length after the 26-byte magic and the version, then the header.
  uint64_t size = 0;
  std::memcpy(&size, bytes.data() + 30, sizeof(size));
  const nlohmann::json header = nlohmann::json::parse(bytes.substr(38, size));
  auto write_with = [&](const nlohmann::json& changed) {
    const std::string text = changed.dump();
    const uint64_t new_size = text.size();
    const std::string length(reinterpret_cast<const char*>(&new_size), sizeof(new_size));
    WriteBytes(path, bytes.substr(0, 30) + length + text + bytes.substr(38 + size));
  };
  write_with(header);
  ASSERT_TRUE(ReadMapperCheckpoint(path, fingerprint).has_value());
  for (const auto& [key, value] : {std::pair<std::string, nlohmann::json>{"loop_cooldown", 1e300},
                                   {"loop_cooldown", 2.5},
                                   {"last_global_size", -1},
                                   {"recent_frames", {-3}},
                                   {"loop_window", {4294967296ull}}}) {
    nlohmann::json changed = header;
    changed[key] = value;
    write_with(changed);
    EXPECT_FALSE(ReadMapperCheckpoint(path, fingerprint)) << key << " " << value.dump();
  }
  nlohmann::json changed = header;
  changed["report"]["counts"][0] = 1e20;
  write_with(changed);
  EXPECT_FALSE(ReadMapperCheckpoint(path, fingerprint)) << "a report count of 1e20";
}

}  // namespace
}  // namespace loopsfm
