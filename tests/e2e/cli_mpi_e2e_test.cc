// loopsfm under mpirun (OpenMPI): the ranks share extraction and matching and write the
// database one process writes; a rank that dies fails the run, and the rerun resumes.
// Skipped, saying why, where mpirun or an MPI build of loopsfm is absent.

#include <gtest/gtest.h>

#include <iostream>

#include "cli_test_util.h"

namespace loopsfm::e2e {
namespace {

// The launcher, allowed to run as root (CI containers), ranks allowed past the cores.
std::string Mpirun(int num_ranks) {
  return fmt::format(
      "env OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 "
      "OMPI_MCA_btl_vader_single_copy_mechanism=none mpirun -np {} --oversubscribe {}",
      num_ranks, ShellQuote(LoopsfmBinary().string()));
}

std::string Args(const std::vector<std::string>& args) {
  std::string line;
  for (const std::string& arg : args) line += " " + ShellQuote(arg);
  return line;
}

class CliMpiTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir("suite");
    if (!OnPath("mpirun")) {
      skip_ = "mpirun is not installed (scripts/setup installs openmpi-bin)";
      return;
    }
    const CommandResult version = RunLoopsfm({"--version"});
    if (version.output.find("MPI: yes") == std::string::npos) {
      skip_ = "this loopsfm was built without MPI (libopenmpi-dev)";
      return;
    }
    const CommandResult synth =
        RunLoopsfm({"-q", "synth", "cylinder", "--video", "-o", Scene().string(), "--frames",
                    "30", "--width", "320", "--height", "240"});
    ASSERT_EQ(synth.exit_code, 0) << synth;
    // The one-process database the ranks must reproduce.
    for (const char* stage : {"extract", "match"}) {
      const CommandResult run = RunLoopsfm(StageArgs(stage, Reference()));
      ASSERT_EQ(run.exit_code, 0) << run;
    }
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    if (!skip_.empty()) GTEST_SKIP() << skip_;
  }

  static fs::path Scene() { return dir_->path() / "scene"; }
  static fs::path Reference() { return dir_->path() / "one_process.db"; }
  static std::vector<std::string> StageArgs(const std::string& stage, const fs::path& db) {
    std::vector<std::string> args = {"-q", stage};
    if (stage == "extract") {
      args.insert(args.end(), {(Scene() / "video.mp4").string(), "--every", "2"});
    }
    args.insert(args.end(), {"-d", db.string()});
    return args;
  }

  static TempDir* dir_;
  static std::string skip_;
};

TempDir* CliMpiTest::dir_ = nullptr;
std::string CliMpiTest::skip_;

TEST_F(CliMpiTest, DatabasesFromTwoAndFourRanksAreTheOneProcessDatabase) {
  const DatabaseSnapshot reference = SnapshotDatabase(Reference());
  ASSERT_GE(reference.frames.size(), 14u);
  ASSERT_GE(reference.verified.size(), 20u);
  for (int num_ranks : {2, 4}) {
    TempDir dir(std::to_string(num_ranks));
    const fs::path db = dir / "ranks.db";
    for (const char* stage : {"extract", "match"}) {
      const CommandResult run = RunShell(Mpirun(num_ranks) + Args(StageArgs(stage, db)));
      ASSERT_EQ(run.exit_code, 0) << run;
    }
    EXPECT_TRUE(SnapshotDatabase(db) == reference)
        << num_ranks << " ranks wrote another database: " << SnapshotDatabase(db) << " against "
        << reference;
  }
}

// reconstruct under mpirun: the ranks share extraction and matching (the log says how), rank
// 0 maps; the database and the model are those of one process.
TEST_F(CliMpiTest, ReconstructUnderMpirunIsReconstructInOneProcess) {
  TempDir dir;
  const std::vector<std::string> args = {
      "reconstruct", (Scene() / "video.mp4").string(), "--every", "2", "--threads", "1",
      "--intrinsics", (Scene() / "intrinsics.txt").string(), "-o"};
  const CommandResult shared = RunShell(Mpirun(2) + Args(args) + Args({(dir / "two").string()}));
  ASSERT_EQ(shared.exit_code, 0) << shared;
  EXPECT_NE(shared.output.find("MPI: 2 ranks share extraction, matching and segments"),
            std::string::npos)
      << shared;
  EXPECT_NE(shared.output.find("match: pairs per rank: "), std::string::npos) << shared;
  std::vector<std::string> alone_args = args;
  alone_args.push_back((dir / "one").string());
  const CommandResult alone = RunLoopsfm(alone_args);
  ASSERT_EQ(alone.exit_code, 0) << alone;
  EXPECT_TRUE(SnapshotDatabase(dir / "two" / "database.db") ==
              SnapshotDatabase(dir / "one" / "database.db"));
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) {
    EXPECT_TRUE(ReadFileBytes(dir / "two" / "sparse" / "0" / file) ==
                ReadFileBytes(dir / "one" / "sparse" / "0" / file))
        << file;
  }
}

// A wrong command line under mpirun: rank 0 says what is wrong, the other ranks end, and
// the run exits with code 2 (no rank waits for work forever).
TEST_F(CliMpiTest, AWrongCommandLineEndsEveryRank) {
  const CommandResult run =
      RunShell("timeout 60 " + Mpirun(2) +
               Args({"reconstruct", (Scene() / "video.mp4").string(), "-o",
                     (dir_->path() / "flag_out").string(), "--no-such-flag"}));
  EXPECT_EQ(run.exit_code, 2) << run;
  EXPECT_NE(run.output.find("--no-such-flag"), std::string::npos) << run;
  const CommandResult missing = RunShell(
      "timeout 60 " + Mpirun(2) +
      Args({"reconstruct", (dir_->path() / "missing.mp4").string(), "-o",
            (dir_->path() / "missing_out").string()}));
  EXPECT_EQ(missing.exit_code, 2) << missing;
  EXPECT_NE(missing.output.find("missing.mp4"), std::string::npos) << missing;
}

// Rank 1 is killed once rank 0 has stored the first pairs: mpirun ends the run with an error
// naming the process, the pairs stored are kept, and a rerun in one process matches only
// the others and ends with the database a run that was never killed writes.
TEST_F(CliMpiTest, ARankThatDiesFailsTheRunAndTheRerunResumes) {
  if (!OnPath("sqlite3")) GTEST_SKIP() << "sqlite3 is not installed (scripts/setup installs it)";
  TempDir dir;
  // Enough pairs that the run is still matching when the first are stored: the pairs are
  // stored 512 at a time (256 a rank), and 120 frames make 7,140 pairs, 14 stores. With 40
  // frames (780 pairs, two stores) the second took about 0.1 s, less than the killer
  // needs on a busy machine, and the killed run had kept every pair.
  const CommandResult synth =
      RunLoopsfm({"-q", "synth", "cylinder", "--video", "-o", (dir / "scene").string(),
                  "--frames", "120", "--width", "480", "--height", "360"});
  ASSERT_EQ(synth.exit_code, 0) << synth;
  const fs::path db = dir / "killed.db", reference = dir / "reference.db";
  for (const fs::path& path : {db, reference}) {
    const CommandResult extract = RunLoopsfm(
        {"-q", "extract", (dir / "scene" / "video.mp4").string(), "--every", "1", "-d",
         path.string()});
    ASSERT_EQ(extract.exit_code, 0) << extract;
  }
  const std::vector<std::string> match = {"match", "--pairs", "exhaustive", "--threads", "1",
                                          "-d"};
  std::vector<std::string> reference_match = match;
  reference_match.push_back(reference.string());
  ASSERT_EQ(RunLoopsfm(reference_match).exit_code, 0);

  const std::string stored_pairs = fmt::format(
      "$(sqlite3 {} 'SELECT count(*) FROM matches' 2>/dev/null || echo 0)", ShellQuote(db.string()));
  const std::string kill_rank1 = fmt::format(
      "for i in $(seq 1 3000); do "
      "  if [ {} -gt 0 ]; then "
      "    for p in $(pgrep -f {}); do "
      "      if tr '\\0' '\\n' < /proc/$p/environ 2>/dev/null | "
      "         grep -qx OMPI_COMM_WORLD_RANK=1; then kill -9 $p; exit 0; fi; "
      "    done; "
      "  fi; sleep 0.01; "
      "done",
      stored_pairs, ShellQuote(db.string()));
  const CommandResult killed = RunShell("{ (" + kill_rank1 + ") & " + Mpirun(2) + Args(match) +
                                        Args({db.string()}) + "; rc=$?; wait; exit $rc; }");
  EXPECT_NE(killed.exit_code, 0) << killed;
  EXPECT_NE(killed.output.find("signal 9"), std::string::npos) << killed;
  const size_t kept = SnapshotDatabase(db).pair_bytes.size();
  const size_t all = SnapshotDatabase(reference).pair_bytes.size();
  std::cout << "[ info     ] pairs kept from the killed run: " << kept << " of " << all << "\n";
  EXPECT_GT(kept, 0u);
  EXPECT_LT(kept, all);

  std::vector<std::string> rerun_args = match;
  rerun_args.push_back(db.string());
  const CommandResult rerun = RunLoopsfm(rerun_args);
  ASSERT_EQ(rerun.exit_code, 0) << rerun;
  EXPECT_NE(rerun.output.find(fmt::format("({} already stored)", kept)), std::string::npos)
      << rerun;
  EXPECT_TRUE(SnapshotDatabase(db) == SnapshotDatabase(reference));
}

}  // namespace
}  // namespace loopsfm::e2e
