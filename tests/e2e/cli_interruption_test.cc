// kill -9 in the middle of mapping, then the same command again: the rerun recomputes
// nothing that was stored (frames, pairs), goes on from the last mapping checkpoint, and
// ends with the model an uninterrupted run makes, byte for byte (one thread, default seed).
// A run killed while mapping leaves the model of an earlier run as it was.
// bench/interruption/kill_campaign.sh does the same at random moments in every stage.

#include <nlohmann/json.hpp>

#include <cstring>

#include "cli_test_util.h"

namespace loopsfm::e2e {
namespace {

// The JSON header of a mapping checkpoint (pipeline/checkpoint_file.h) whose first line is
// `magic_size` bytes long: 26 for the incremental mapper's, 33 for the global mapper's.
nlohmann::json CheckpointHeader(const fs::path& path, size_t magic_size = 26) {
  const std::string bytes = ReadFileBytes(path);
  const size_t kLengthAt = magic_size + 4;
  if (bytes.size() < kLengthAt + 8) return nullptr;
  uint64_t length = 0;
  std::memcpy(&length, bytes.data() + kLengthAt, 8);
  if (length > bytes.size() - kLengthAt - 8) return nullptr;
  return nlohmann::json::parse(bytes.substr(kLengthAt + 8, length), nullptr, false);
}

std::vector<std::string> ReconstructArgs(const fs::path& video, const fs::path& out) {
  return {"--threads", "1", "reconstruct", video.string(), "-o", out.string(), "--export",
          "colmap,tum", "--checkpoint-every", "0.001"};
}

std::vector<std::string> GlobalArgs(const fs::path& video, const fs::path& out) {
  return {"--threads", "1", "reconstruct", video.string(), "-o", out.string(),
          "--export", "colmap,tum", "--mapper", "global"};
}

// The 100-frame street video both tests map.
fs::path StreetVideo(const TempDir& dir) {
  const CommandResult synth =
      RunLoopsfm({"-q", "synth", "street", "-o", (dir / "scene").string(), "--video", "--frames",
                  "100", "--width", "320", "--height", "240"});
  EXPECT_EQ(synth.exit_code, 0) << synth;
  return dir / "scene" / "video.mp4";
}

// Runs loopsfm with `args` (output to `log`) and kills it with -9 `delay` seconds after
// `file` appears.
CommandResult KilledAfter(const std::vector<std::string>& args, const fs::path& file,
                          const std::string& delay, const fs::path& log) {
  std::string command;
  for (const std::string& arg : args) command += " " + ShellQuote(arg);
  return RunShell(fmt::format(
      "{}{} > {} 2>&1 & pid=$!; while [ ! -f {} ] && kill -0 $pid 2>/dev/null; do sleep 0.02; "
      "done; sleep {}; kill -9 $pid; wait $pid",
      ShellQuote(LoopsfmBinary().string()), command, ShellQuote(log.string()),
      ShellQuote(file.string()), delay));
}

void ExpectSameResult(const fs::path& a, const fs::path& b) {
  for (const char* file : {"sparse/0/cameras.bin", "sparse/0/images.bin",
                           "sparse/0/points3D.bin", "trajectory.txt"}) {
    ASSERT_TRUE(fs::exists(a / file)) << a / file;
    EXPECT_TRUE(ReadFileBytes(a / file) == ReadFileBytes(b / file)) << file << " differs";
  }
}

TEST(Interruption, KilledWhileMappingGoesOnFromTheCheckpointToTheSameModel) {
  TempDir dir;
  const fs::path video = StreetVideo(dir);
  const CommandResult reference = RunLoopsfm(ReconstructArgs(video, dir / "reference"));
  ASSERT_EQ(reference.exit_code, 0) << reference;

  // Killed two seconds after the first checkpoint (they are written before every
  // registration here), well before mapping ends.
  const fs::path checkpoint = dir / "killed" / "mapper_checkpoint.bin";
  const CommandResult killed = KilledAfter(ReconstructArgs(video, dir / "killed"), checkpoint,
                                           "2", dir / "killed.log");
  ASSERT_EQ(killed.exit_code, 128 + 9) << killed << "\n" << ReadFileBytes(dir / "killed.log");
  ASSERT_FALSE(fs::exists(dir / "killed" / "sparse")) << "mapping ended before the kill";
  const nlohmann::json header = CheckpointHeader(checkpoint);
  ASSERT_TRUE(header.is_object()) << "the checkpoint left by the kill cannot be read";
  EXPECT_FALSE(header.at("finished").get<bool>());
  const int registered_before = header.at("report").at("counts").at(1).get<int>();
  EXPECT_GT(registered_before, 2);

  const CommandResult rerun = RunLoopsfm(ReconstructArgs(video, dir / "killed"));
  ASSERT_EQ(rerun.exit_code, 0) << rerun;
  EXPECT_NE(rerun.output.find("(0 new)"), std::string::npos) << "frames extracted again" << rerun;
  EXPECT_NE(rerun.output.find("(0 matched now"), std::string::npos) << "pairs matched again" << rerun;
  EXPECT_NE(rerun.output.find("going on from a checkpoint"), std::string::npos) << rerun;
  ExpectSameResult(dir / "reference", dir / "killed");

  // Once more: mapping had finished, nothing is mapped again, the result is the same.
  const CommandResult again = RunLoopsfm(ReconstructArgs(video, dir / "killed"));
  ASSERT_EQ(again.exit_code, 0) << again;
  EXPECT_NE(again.output.find("mapping had finished"), std::string::npos) << again;
  ExpectSameResult(dir / "reference", dir / "killed");

  // Mapping again with other options (a new checkpoint replaces the old one), killed in the
  // middle: the earlier run's model is still there, unchanged.
  fs::copy_file(checkpoint, dir / "checkpoint.before");
  std::string other;
  for (const std::string& arg : ReconstructArgs(video, dir / "killed")) other += " " + ShellQuote(arg);
  const CommandResult killed_again = RunShell(fmt::format(
      "{}{} --loop-closing none > {} 2>&1 & pid=$!; while cmp -s {} {} && kill -0 $pid "
      "2>/dev/null; do sleep 0.05; done; sleep 1; kill -9 $pid; wait $pid",
      ShellQuote(LoopsfmBinary().string()), other, ShellQuote((dir / "killed2.log").string()),
      ShellQuote(checkpoint.string()), ShellQuote((dir / "checkpoint.before").string())));
  ASSERT_EQ(killed_again.exit_code, 128 + 9)
      << killed_again << "\n" << ReadFileBytes(dir / "killed2.log");
  ExpectSameResult(dir / "reference", dir / "killed");

  // Ctrl-C (SIGINT) while mapping with those options: the run stops at its next registration,
  // says so and exits 130, leaving the earlier model as it was; the same command then goes on
  // from the checkpoint and finishes.
  fs::copy_file(checkpoint, dir / "checkpoint.before", fs::copy_options::overwrite_existing);
  const CommandResult interrupted = RunShell(fmt::format(
      "{}{} --loop-closing none > {} 2>&1 & pid=$!; while cmp -s {} {} && kill -0 $pid "
      "2>/dev/null; do sleep 0.05; done; kill -INT $pid; wait $pid",
      ShellQuote(LoopsfmBinary().string()), other, ShellQuote((dir / "interrupted.log").string()),
      ShellQuote(checkpoint.string()), ShellQuote((dir / "checkpoint.before").string())));
  const std::string interrupted_log = ReadFileBytes(dir / "interrupted.log");
  ASSERT_EQ(interrupted.exit_code, 130) << interrupted << "\n" << interrupted_log;
  EXPECT_NE(interrupted_log.find("loopsfm: stopped: asked to stop during map"), std::string::npos)
      << interrupted_log;
  ExpectSameResult(dir / "reference", dir / "killed");
  std::vector<std::string> without_loops = ReconstructArgs(video, dir / "killed");
  without_loops.insert(without_loops.end(), {"--loop-closing", "none"});
  const CommandResult resumed = RunLoopsfm(without_loops);
  ASSERT_EQ(resumed.exit_code, 0) << resumed;
  EXPECT_NE(resumed.output.find("going on from a checkpoint"), std::string::npos) << resumed;

  // --checkpoint-every 0 neither reads nor writes one; --overwrite deletes it.
  const CommandResult overwrite = RunLoopsfm({"-q", "--threads", "1", "reconstruct",
                                              video.string(), "-o", (dir / "killed").string(),
                                              "--export", "none", "--overwrite",
                                              "--checkpoint-every", "0"});
  ASSERT_EQ(overwrite.exit_code, 0) << overwrite;
  EXPECT_FALSE(fs::exists(checkpoint));
}

// The global mapper saves after each stage: killed after its first checkpoint, the rerun
// goes on from the last stage it saved to the uninterrupted run's model, byte for byte.
TEST(Interruption, KilledWhileGlobalMappingGoesOnFromTheLastStage) {
  TempDir dir;
  const fs::path video = StreetVideo(dir);
  const CommandResult reference = RunLoopsfm(GlobalArgs(video, dir / "reference"));
  ASSERT_EQ(reference.exit_code, 0) << reference;

  const fs::path checkpoint = dir / "killed" / "global_mapper_checkpoint.bin";
  const CommandResult killed =
      KilledAfter(GlobalArgs(video, dir / "killed"), checkpoint, "0", dir / "killed.log");
  ASSERT_EQ(killed.exit_code, 128 + 9) << killed << "\n" << ReadFileBytes(dir / "killed.log");
  ASSERT_FALSE(fs::exists(dir / "killed" / "sparse")) << "mapping ended before the kill";
  const nlohmann::json header = CheckpointHeader(checkpoint, 33);
  ASSERT_TRUE(header.is_object()) << "the checkpoint left by the kill cannot be read";
  ASSERT_EQ(header.at("components").size(), 1u) << header.dump();
  EXPECT_FALSE(header.at("components").at(0).at("done").get<bool>());

  const CommandResult rerun = RunLoopsfm(GlobalArgs(video, dir / "killed"));
  ASSERT_EQ(rerun.exit_code, 0) << rerun;
  EXPECT_NE(rerun.output.find("going on from its checkpoint, 0 of 1 component mapped"),
            std::string::npos)
      << rerun;
  ExpectSameResult(dir / "reference", dir / "killed");

  // Once more: every stage is done, nothing is mapped again.
  const CommandResult again = RunLoopsfm(GlobalArgs(video, dir / "killed"));
  ASSERT_EQ(again.exit_code, 0) << again;
  EXPECT_NE(again.output.find("1 of 1 component mapped"), std::string::npos) << again;
  EXPECT_EQ(again.output.find("global mapper: rotations of"), std::string::npos) << again;
  ExpectSameResult(dir / "reference", dir / "killed");
}

}  // namespace
}  // namespace loopsfm::e2e
