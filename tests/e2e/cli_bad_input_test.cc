// Bad input to the CLI: every case exits with code 2 and a message that names the problem,
// and a database that already holds frames, features and matches is left exactly as it was.
// Inputs that are only partly bad (an unreadable image in a folder, a video cut short) are
// used as far as they go, with a warning, and exit 0. Re-running a stage resumes: nothing
// is extracted or matched twice.

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cstdio>
#include <iostream>
#include <memory>
#include <regex>
#include <set>
#include <sstream>

#include "cli_test_util.h"
#include "loopsfm/matching/descriptor_matcher.h"

namespace loopsfm::e2e {
namespace {

constexpr int kExitBadInput = 2;
constexpr int kNumGoodImages = 6;

// True when `text` matches the ECMAScript regex `pattern`, ignoring case.
bool ContainsRegex(const std::string& text, const std::string& pattern) {
  return std::regex_search(text, std::regex(pattern, std::regex::icase | std::regex::ECMAScript));
}

// The line that main() prints for a user error.
std::string ErrorLine(const CommandResult& result) {
  std::istringstream lines(result.output);
  std::string line;
  while (std::getline(lines, line)) {
    if (line.rfind("loopsfm: error:", 0) == 0) return line;
  }
  return {};
}

// Inputs shared by all tests of the suite, rendered once.
struct Assets {
  fs::path dir;
  fs::path good_images;      // kNumGoodImages frames 240x180 of the synthetic cylinder
  fs::path other_size_image; // one 200x150 frame
  fs::path video;            // 16 frames 160x120, H.264 in mp4 (index at the end)
  fs::path stored_db;        // good_images extracted and matched exhaustively
  DatabaseSnapshot stored;   // its content
  std::string error;         // why the assets could not be made
};

class CliBadInputTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    assets_ = new Assets;
    Assets& a = *assets_;
    a.dir = fs::temp_directory_path() / fmt::format("loopsfm_e2e_{}_bad_input_assets", getpid());
    fs::remove_all(a.dir);
    fs::create_directories(a.dir);
    auto run = [&](const std::vector<std::string>& args) {
      if (!a.error.empty()) return;
      const CommandResult result = RunLoopsfm(args);
      if (result.exit_code != 0) {
        std::ostringstream message;
        message << "preparing the inputs failed:" << result;
        a.error = message.str();
      }
    };
    run({"-q", "synth", "cylinder", "-o", (a.dir / "cyl").string(), "--frames", "36", "--width",
         "240", "--height", "180"});
    run({"-q", "synth", "cylinder", "-o", (a.dir / "small").string(), "--frames", "2",
         "--width", "200", "--height", "150"});
    run({"-q", "synth", "cylinder", "-o", (a.dir / "vid").string(), "--video", "--frames", "16",
         "--width", "160", "--height", "120"});
    if (!a.error.empty()) return;
    // Six neighbouring frames (10 degrees apart) so that most pairs verify.
    a.good_images = a.dir / "good";
    fs::create_directories(a.good_images);
    for (int i = 0; i < kNumGoodImages; ++i) {
      const std::string name = fmt::format("frame_{:06d}.png", i);
      fs::copy_file(a.dir / "cyl" / "images" / name, a.good_images / name);
    }
    a.other_size_image = a.dir / "small" / "images" / "frame_000000.png";
    a.video = a.dir / "vid" / "video.mp4";
    a.stored_db = a.dir / "stored.db";
    run({"-q", "extract", a.good_images.string(), "-d", a.stored_db.string()});
    run({"-q", "match", "-d", a.stored_db.string(), "--pairs", "exhaustive"});
    if (!a.error.empty()) return;
    a.stored = SnapshotDatabase(a.stored_db);
    if (a.stored.frames.size() != kNumGoodImages || a.stored.verified.empty()) {
      a.error = fmt::format("the stored database holds {} frames and {} verified pairs; expected "
                            "{} frames and some verified pairs",
                            a.stored.frames.size(), a.stored.verified.size(), kNumGoodImages);
    }
  }

  static void TearDownTestSuite() {
    if (assets_ != nullptr && !::testing::UnitTest::GetInstance()->Failed()) {
      std::error_code ignored;
      fs::remove_all(assets_->dir, ignored);
    }
    delete assets_;
    assets_ = nullptr;
  }

  void SetUp() override {
    ASSERT_TRUE(assets_->error.empty()) << assets_->error;
    tmp_ = std::make_unique<TempDir>();
    // A database that already holds work, used as the target of failing commands.
    db_ = tmp_->path() / "stored.db";
    fs::copy_file(assets_->stored_db, db_);
  }

  // The command failed as a user error: exit code 2 and a "loopsfm: error:" line.
  static void ExpectUserError(const CommandResult& result) {
    EXPECT_EQ(result.exit_code, kExitBadInput) << result;
    EXPECT_FALSE(ErrorLine(result).empty()) << "no 'loopsfm: error:' line" << result;
  }

  // The stored database still holds exactly what it held.
  void ExpectStoredDatabaseIntact() const {
    EXPECT_EQ(SnapshotDatabase(db_), assets_->stored) << "the stored database changed";
  }

  const fs::path& dir() const { return tmp_->path(); }

  static Assets* assets_;
  std::unique_ptr<TempDir> tmp_;
  fs::path db_;
};

Assets* CliBadInputTest::assets_ = nullptr;

TEST_F(CliBadInputTest, MissingInputPath) {
  const fs::path missing = dir() / "no_such_video.mp4";
  const CommandResult extract = RunLoopsfm({"extract", missing.string(), "-d", db_.string()});
  ExpectUserError(extract);
  EXPECT_TRUE(ContainsRegex(ErrorLine(extract), "no_such_video\\.mp4.*does not exist"))
      << extract;
  ExpectStoredDatabaseIntact();

  const CommandResult reconstruct =
      RunLoopsfm({"reconstruct", missing.string(), "-o", (dir() / "out").string()});
  ExpectUserError(reconstruct);
  EXPECT_TRUE(ContainsRegex(ErrorLine(reconstruct), "no_such_video\\.mp4.*does not exist"))
      << reconstruct;
}

TEST_F(CliBadInputTest, TextFileNamedMp4) {
  const fs::path fake = dir() / "notes.mp4";
  WriteTextFile(fake, "these are my notes, not a video\n");
  const CommandResult result = RunLoopsfm({"extract", fake.string(), "-d", db_.string()});
  ExpectUserError(result);
  const std::string error = ErrorLine(result);
  EXPECT_TRUE(ContainsRegex(error, "notes\\.mp4")) << result;
  EXPECT_TRUE(ContainsRegex(error, "video")) << result;
  ExpectStoredDatabaseIntact();
}

TEST_F(CliBadInputTest, SingleImageFile) {
  const fs::path image = assets_->good_images / "frame_000000.png";
  const CommandResult result = RunLoopsfm({"extract", image.string(), "-d", db_.string()});
  ExpectUserError(result);
  const std::string error = ErrorLine(result);
  EXPECT_TRUE(ContainsRegex(error, "frame_000000\\.png")) << result;
  EXPECT_TRUE(ContainsRegex(error, "single image")) << result;
  EXPECT_TRUE(ContainsRegex(error, "folder")) << "the message should say to pass a folder"
                                              << result;
  ExpectStoredDatabaseIntact();
}

TEST_F(CliBadInputTest, EmptyFolder) {
  const fs::path empty = dir() / "empty_folder";
  fs::create_directories(empty);
  const CommandResult result = RunLoopsfm({"extract", empty.string(), "-d", db_.string()});
  ExpectUserError(result);
  const std::string error = ErrorLine(result);
  EXPECT_TRUE(ContainsRegex(error, "empty_folder")) << result;
  EXPECT_TRUE(ContainsRegex(error, "no images")) << result;
  ExpectStoredDatabaseIntact();
}

TEST_F(CliBadInputTest, VideoTruncatedToItsHeader) {
  const fs::path cut = dir() / "cut.mp4";
  fs::copy_file(assets_->video, cut);
  fs::resize_file(cut, 300);
  const CommandResult result = RunLoopsfm({"extract", cut.string(), "-d", db_.string()});
  ExpectUserError(result);
  const std::string error = ErrorLine(result);
  EXPECT_TRUE(ContainsRegex(error, "cut\\.mp4")) << result;
  EXPECT_TRUE(ContainsRegex(error, "damaged|truncated|corrupt")) << result;
  ExpectStoredDatabaseIntact();
}

// An mp4 written front to back keeps its index (the moov box) at the end: cut in half,
// not one frame can be located, so it is an error like a header-only file.
TEST_F(CliBadInputTest, VideoTruncatedBeforeItsIndex) {
  const fs::path cut = dir() / "cut.mp4";
  fs::copy_file(assets_->video, cut);
  fs::resize_file(cut, fs::file_size(cut) / 2);
  const CommandResult result = RunLoopsfm({"extract", cut.string(), "-d", db_.string()});
  ExpectUserError(result);
  const std::string error = ErrorLine(result);
  EXPECT_TRUE(ContainsRegex(error, "cut\\.mp4")) << result;
  EXPECT_TRUE(ContainsRegex(error, "damaged|truncated|corrupt")) << result;
  ExpectStoredDatabaseIntact();
}

// With the index in front (`-movflags +faststart`, as streaming encoders and phones often
// write), a video cut in half still decodes up to the cut: those frames are extracted, a
// warning says the video ended early, and the run succeeds.
TEST_F(CliBadInputTest, VideoTruncatedInHalfKeepsFramesBeforeTheCut) {
  if (!OnPath("ffmpeg") || !OnPath("ffprobe")) {
    GTEST_SKIP() << "ffmpeg/ffprobe not on PATH; they are needed to move the mp4 index to the "
                    "front (scripts/setup installs them)";
  }
  const fs::path faststart = dir() / "faststart.mp4";
  const CommandResult remux =
      RunShell(fmt::format("ffmpeg -v error -y -i {} -c copy -movflags +faststart {}",
                           ShellQuote(assets_->video.string()), ShellQuote(faststart.string())));
  ASSERT_EQ(remux.exit_code, 0) << remux;
  const uintmax_t cut_at = fs::file_size(faststart) / 2;

  // Frames whose compressed packet lies wholly before the cut.
  const CommandResult packets = RunShell(fmt::format(
      "ffprobe -v error -select_streams v:0 -show_entries packet=pos,size -of csv=p=0 {}",
      ShellQuote(faststart.string())));
  ASSERT_EQ(packets.exit_code, 0) << packets;
  int num_packets = 0, complete = 0;
  std::istringstream lines(packets.output);
  std::string line;
  while (std::getline(lines, line)) {
    unsigned long long pos = 0, size = 0;
    if (std::sscanf(line.c_str(), "%llu,%llu", &pos, &size) != 2) continue;
    ++num_packets;
    if (pos + size <= cut_at) ++complete;
  }
  ASSERT_EQ(num_packets, 16) << packets;
  ASSERT_GE(complete, 4) << "the cut should leave several whole frames" << packets;
  ASSERT_LT(complete, 16) << packets;

  const fs::path cut = dir() / "cut.mp4";
  fs::copy_file(faststart, cut);
  fs::resize_file(cut, cut_at);
  const fs::path db = dir() / "new.db";
  // Every frame (not adaptive keyframes): the frames before the cut are what is checked.
  const CommandResult result =
      RunLoopsfm({"extract", cut.string(), "-d", db.string(), "--every", "1"});
  ASSERT_EQ(result.exit_code, 0) << result;
  EXPECT_TRUE(ContainsRegex(result.output, "warn.*cut\\.mp4.*(truncated|corrupt)")) << result;

  const DatabaseSnapshot stored = SnapshotDatabase(db);
  // Every stored frame lies before the cut, and they are the video's first frames in order.
  // (The decoder may hold back its last frames or two at the error, so at least half of
  // the whole frames are required, not all.)
  EXPECT_LE(stored.frames.size(), static_cast<size_t>(complete)) << result;
  EXPECT_GE(stored.frames.size(), static_cast<size_t>((complete + 1) / 2))
      << complete << " frames lie wholly before the cut" << result;
  for (size_t i = 0; i < stored.frames.size(); ++i) {
    EXPECT_EQ(std::get<2>(stored.frames[i]), fmt::format("frame_{:06d}.png", i));
    EXPECT_FALSE(stored.keypoint_bytes[i].empty()) << "frame " << i << " has no features";
  }
  std::cout << "[ info     ] " << stored.frames.size() << " of " << complete
            << " whole frames before the cut extracted\n";
}

TEST_F(CliBadInputTest, UnreadableImageIsSkippedAndCounted) {
  const fs::path folder = dir() / "images";
  fs::copy(assets_->good_images, folder);
  WriteTextFile(folder / "frame_000002.png", "not an image\n");
  const fs::path db = dir() / "new.db";
  const CommandResult result = RunLoopsfm({"extract", folder.string(), "-d", db.string()});
  ASSERT_EQ(result.exit_code, 0) << result;
  EXPECT_TRUE(ContainsRegex(result.output, "warn.*frame_000002\\.png")) << result;
  EXPECT_TRUE(ContainsRegex(result.output, "\\b1 unreadable")) << result;

  const DatabaseSnapshot stored = SnapshotDatabase(db);
  std::set<std::string> names;
  for (const auto& frame : stored.frames) names.insert(std::get<2>(frame));
  const std::set<std::string> expected = {"frame_000000.png", "frame_000001.png",
                                          "frame_000003.png", "frame_000004.png",
                                          "frame_000005.png"};
  EXPECT_EQ(names, expected);
  for (const std::string& keypoints : stored.keypoint_bytes) EXPECT_FALSE(keypoints.empty());
}

TEST_F(CliBadInputTest, ImagesOfDifferentSizesGetOneCameraPerSize) {
  const fs::path folder = dir() / "images";
  fs::copy(assets_->good_images, folder);
  fs::copy_file(assets_->other_size_image, folder / "frame_000003b.png");
  const fs::path db = dir() / "new.db";
  const CommandResult result = RunLoopsfm({"extract", folder.string(), "-d", db.string()});
  ASSERT_EQ(result.exit_code, 0) << result;

  const Database database = Database::Open(db.string());
  ASSERT_EQ(database.NumCameras(), 2u) << result;
  ASSERT_EQ(database.NumFrames(), static_cast<size_t>(kNumGoodImages + 1)) << result;
  for (const Frame& frame : database.ReadFrames()) {
    const std::optional<Camera> camera = database.ReadCamera(frame.camera_id);
    ASSERT_TRUE(camera.has_value()) << frame.name;
    const bool small = frame.name == "frame_000003b.png";
    EXPECT_EQ(camera->width, small ? 200 : 240) << frame.name;
    EXPECT_EQ(camera->height, small ? 150 : 180) << frame.name;
  }
}

TEST_F(CliBadInputTest, TextFileAsDatabaseIsLeftUnchanged) {
  const fs::path db = dir() / "notes.db";
  const std::string text = "my shopping list\neggs\nmilk\n";
  WriteTextFile(db, text);
  const CommandResult extract =
      RunLoopsfm({"extract", assets_->good_images.string(), "-d", db.string()});
  ExpectUserError(extract);
  EXPECT_TRUE(ContainsRegex(ErrorLine(extract), "notes\\.db.*not a SQLite")) << extract;
  EXPECT_EQ(ReadFileBytes(db), text);

  const CommandResult match = RunLoopsfm({"match", "-d", db.string()});
  ExpectUserError(match);
  EXPECT_TRUE(ContainsRegex(ErrorLine(match), "notes\\.db.*not a SQLite")) << match;
  EXPECT_EQ(ReadFileBytes(db), text);
}

TEST_F(CliBadInputTest, ForeignSqliteDatabaseIsLeftUnchanged) {
  const fs::path db = dir() / "inventory.db";
  {
    sqlite3* handle = nullptr;
    ASSERT_EQ(sqlite3_open(db.c_str(), &handle), SQLITE_OK);
    char* message = nullptr;
    const int rc = sqlite3_exec(handle,
                                "CREATE TABLE stock(item TEXT, count INTEGER);"
                                "INSERT INTO stock VALUES ('bolts', 120), ('nuts', 80);",
                                nullptr, nullptr, &message);
    EXPECT_EQ(rc, SQLITE_OK) << (message ? message : "");
    sqlite3_free(message);
    sqlite3_close(handle);
  }
  const std::string bytes = ReadFileBytes(db);
  ASSERT_FALSE(bytes.empty());

  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"extract", assets_->good_images.string(), "-d", db.string()},
        std::vector<std::string>{"match", "-d", db.string(), "--pairs", "exhaustive"},
        std::vector<std::string>{"tracks", "-d", db.string()}}) {
    const CommandResult result = RunLoopsfm(args);
    ExpectUserError(result);
    const std::string error = ErrorLine(result);
    EXPECT_TRUE(ContainsRegex(error, "inventory\\.db")) << result;
    EXPECT_TRUE(ContainsRegex(error, "stock")) << "the message should name the foreign table"
                                               << result;
    EXPECT_EQ(ReadFileBytes(db), bytes) << "the foreign database was modified" << result;
  }
  EXPECT_FALSE(fs::exists(dir() / "inventory.db-journal"));
  EXPECT_FALSE(fs::exists(dir() / "inventory.db-wal"));
}

TEST_F(CliBadInputTest, MatchWithoutDatabaseSaysToRunExtract) {
  const fs::path db = dir() / "never_extracted.db";
  const CommandResult result = RunLoopsfm({"match", "-d", db.string(), "--pairs", "exhaustive"});
  ExpectUserError(result);
  const std::string error = ErrorLine(result);
  EXPECT_TRUE(ContainsRegex(error, "never_extracted\\.db.*does not exist")) << result;
  EXPECT_TRUE(ContainsRegex(error, "loopsfm extract")) << result;
  EXPECT_FALSE(fs::exists(db)) << "match must not create an empty database";
}

TEST_F(CliBadInputTest, BadFlagValues) {
  const std::string images = assets_->good_images.string();
  const fs::path new_db = dir() / "new.db";
  struct Case {
    std::vector<std::string> args;
    // What the error line must mention.
    std::string pattern;
  };
  const std::vector<Case> cases = {
      {{"extract", images, "-d", db_.string(), "--every", "0"}, "--every.*\\b0\\b"},
      {{"extract", images, "-d", new_db.string(), "--every", "0"}, "--every.*\\b0\\b"},
      {{"extract", images, "-d", db_.string(), "--max-features", "-1"}, "--max-features.*-1"},
      {{"extract", images, "-d", new_db.string(), "--max-features", "-1"}, "--max-features.*-1"},
      {{"match", "-d", db_.string(), "--pairs", "foo"}, "foo.*exhaustive.*sequential"},
      {{"match", "-d", db_.string(), "--ratio", "1.5"}, "ratio.*1\\.5"},
      {{"match", "-d", db_.string(), "--match-kernel", "sse9"}, "match-kernel.*sse9.*avx2"},
      {{"match", "-d", db_.string(), "--overlap", "0"}, "overlap.*\\b0\\b"},
      {{"match", "-d", db_.string(), "--pairs", "vocabtree", "--similarity-out",
        (dir() / "no_such_folder" / "sim.txt").string()},
       "similarity-out.*no_such_folder.*does not exist"},
      {{"match", "-d", db_.string(), "--pairs", "sequential", "--similarity-out",
        (dir() / "sim.txt").string()},
       "similarity-out.*vocabtree"},
      {{"reconstruct", images, "-o", (dir() / "out").string(), "--pairs", "foo"}, "foo"},
      {{"reconstruct", images, "-o", (dir() / "out").string(), "--every", "0"}, "--every"},
  };
  for (const Case& c : cases) {
    const CommandResult result = RunLoopsfm(c.args);
    ExpectUserError(result);
    EXPECT_TRUE(ContainsRegex(ErrorLine(result), c.pattern))
        << "the error should match /" << c.pattern << "/" << result;
  }
  ExpectStoredDatabaseIntact();
  EXPECT_FALSE(fs::exists(new_db)) << "a bad flag must be refused before a database is created";
  EXPECT_FALSE(fs::exists(dir() / "out" / "database.db"))
      << "a bad flag must be refused before the output is created";
}

TEST_F(CliBadInputTest, CommonFlagsWorkAfterTheSubcommand) {
  // -q after the subcommand silences the info log as it does before it.
  const fs::path scene = dir() / "scene";
  const CommandResult loud = RunLoopsfm({"synth", "cylinder", "-o", (dir() / "loud").string(),
                                         "--frames", "2", "--width", "64", "--height", "48"});
  ASSERT_EQ(loud.exit_code, 0) << loud;
  EXPECT_NE(loud.output.find("[info]"), std::string::npos) << loud;
  const CommandResult quiet =
      RunLoopsfm({"synth", "cylinder", "-o", scene.string(), "--frames", "2", "--width", "64",
                  "--height", "48", "-q", "--threads", "1"});
  ASSERT_EQ(quiet.exit_code, 0) << quiet;
  EXPECT_EQ(quiet.output.find("[info]"), std::string::npos) << quiet;
  EXPECT_TRUE(fs::exists(scene / "groundtruth.txt"));
}

TEST_F(CliBadInputTest, MalformedIntrinsicsFileNamesFileAndLine) {
  struct Case {
    std::string name, text;
    int line;
  };
  const std::vector<Case> cases = {
      {"letters.txt", "# PINHOLE width height fx fy cx cy\nPINHOLE 240 180 abc 216 120 90\n", 2},
      {"too_few.txt", "PINHOLE 240 180 216\n", 1},
      {"unknown_model.txt", "# calibrated\n\nFISHEYE_DELUXE 240 180 216 216 120 90\n", 3},
  };
  for (const Case& c : cases) {
    const fs::path file = dir() / c.name;
    WriteTextFile(file, c.text);
    const CommandResult result = RunLoopsfm(
        {"extract", assets_->good_images.string(), "-d", db_.string(), "--intrinsics",
         file.string()});
    ExpectUserError(result);
    EXPECT_TRUE(ContainsRegex(ErrorLine(result), fmt::format("{}:{}\\b", c.name, c.line)))
        << "the error should name " << c.name << ":" << c.line << result;
  }
  ExpectStoredDatabaseIntact();
}

TEST_F(CliBadInputTest, RerunningExtractAndMatchResumes) {
  const fs::path db = dir() / "resume.db";
  const std::string images = assets_->good_images.string();

  const CommandResult first = RunLoopsfm({"extract", images, "-d", db.string()});
  ASSERT_EQ(first.exit_code, 0) << first;
  EXPECT_TRUE(ContainsRegex(first.output, "\\(6 new, 0 already stored\\)")) << first;
  const DatabaseSnapshot extracted = SnapshotDatabase(db);
  ASSERT_EQ(extracted.frames.size(), static_cast<size_t>(kNumGoodImages));

  const CommandResult second = RunLoopsfm({"extract", images, "-d", db.string()});
  ASSERT_EQ(second.exit_code, 0) << second;
  EXPECT_TRUE(ContainsRegex(second.output, "\\(0 new, 6 already stored\\)")) << second;
  EXPECT_EQ(SnapshotDatabase(db), extracted) << "re-running extract changed the database";

  const CommandResult match1 = RunLoopsfm({"match", "-d", db.string(), "--pairs", "exhaustive"});
  ASSERT_EQ(match1.exit_code, 0) << match1;
  EXPECT_TRUE(ContainsRegex(match1.output, "\\b15 pairs \\(0 already stored\\), 15 matched now"))
      << match1;
  const DatabaseSnapshot matched = SnapshotDatabase(db);
  EXPECT_EQ(matched.matches.size(), 15u);
  EXPECT_FALSE(matched.verified.empty());

  const CommandResult match2 = RunLoopsfm({"match", "-d", db.string(), "--pairs", "exhaustive"});
  ASSERT_EQ(match2.exit_code, 0) << match2;
  EXPECT_TRUE(ContainsRegex(match2.output, "\\b15 pairs \\(15 already stored\\), 0 matched now"))
      << match2;
  EXPECT_EQ(SnapshotDatabase(db), matched) << "re-running match changed the database";
}

// Every kernel this CPU runs, named with --match-kernel or LOOPSFM_MATCH_KERNEL, stores the same
// matches and geometries; one it does not run is refused before anything is matched.
TEST_F(CliBadInputTest, EveryMatchingKernelStoresTheSameMatches) {
  std::optional<DatabaseSnapshot> reference;
  for (const DescriptorKernel kernel : AvailableDescriptorKernels()) {
    const std::string name = DescriptorKernelName(kernel);
    const fs::path db = dir() / (name + ".db");
    const CommandResult extracted = RunLoopsfm({"extract", assets_->good_images.string(), "-d", db.string()});
    ASSERT_EQ(extracted.exit_code, 0) << extracted;
    const CommandResult matched =
        kernel == DescriptorKernel::kFloat
            ? RunShell("LOOPSFM_MATCH_KERNEL=float " + ShellQuote(LoopsfmBinary().string()) +
                       " match -d " + ShellQuote(db.string()) + " --pairs exhaustive")
            : RunLoopsfm({"match", "-d", db.string(), "--pairs", "exhaustive", "--match-kernel", name});
    ASSERT_EQ(matched.exit_code, 0) << matched;
    EXPECT_TRUE(ContainsRegex(matched.output, name + " kernel")) << matched;
    const DatabaseSnapshot snapshot = SnapshotDatabase(db);
    EXPECT_EQ(snapshot.matches.size(), 15u) << name;
    if (!reference) {
      reference = snapshot;
    } else {
      EXPECT_EQ(snapshot.matches, reference->matches) << name;
      EXPECT_EQ(snapshot.verified, reference->verified) << name;
    }
  }
  for (const DescriptorKernel kernel : {DescriptorKernel::kAvx512Vnni, DescriptorKernel::kAvx2,
                                        DescriptorKernel::kNeonDotprod, DescriptorKernel::kNeon}) {
    if (DescriptorKernelAvailable(kernel)) continue;
    const CommandResult refused = RunLoopsfm(
        {"match", "-d", db_.string(), "--match-kernel", DescriptorKernelName(kernel)});
    ExpectUserError(refused);
    EXPECT_TRUE(ContainsRegex(ErrorLine(refused), "does not run on this CPU")) << refused;
  }
  ExpectStoredDatabaseIntact();
}

TEST_F(CliBadInputTest, RerunWithOtherInputOrOptionsIsRefused) {
  // db_ holds good_images extracted and matched with the defaults.
  const CommandResult features =
      RunLoopsfm({"extract", assets_->good_images.string(), "-d", db_.string(), "--max-features",
                  "500"});
  ExpectUserError(features);
  EXPECT_TRUE(ContainsRegex(features.output, "sift\\.max_features: 8192 -> 500")) << features;
  EXPECT_TRUE(ContainsRegex(features.output, "--overwrite")) << features;

  // Another folder of images into the same database.
  const fs::path other = dir() / "other";
  fs::create_directories(other);
  int copied = 0;
  for (const auto& entry : fs::directory_iterator(assets_->good_images)) {
    if (copied++ < 3) fs::copy_file(entry.path(), other / entry.path().filename());
  }
  const CommandResult source = RunLoopsfm({"extract", other.string(), "-d", db_.string()});
  ExpectUserError(source);
  EXPECT_TRUE(ContainsRegex(source.output, "source\\.(name|images)")) << source;

  const CommandResult ratio = RunLoopsfm({"match", "-d", db_.string(), "--ratio", "0.7"});
  ExpectUserError(ratio);
  EXPECT_TRUE(ContainsRegex(ratio.output, "matcher\\.max_ratio: 0\\.8 -> 0\\.7")) << ratio;
  ExpectStoredDatabaseIntact();

  // Other pairs with the same matching options add to the stored ones.
  const CommandResult pairs = RunLoopsfm({"match", "-d", db_.string(), "--pairs", "sequential"});
  EXPECT_EQ(pairs.exit_code, 0) << pairs;
}

TEST_F(CliBadInputTest, OneFrameVideoSaysTwoAreNeeded) {
  const fs::path scene = dir() / "one";
  const CommandResult synth = RunLoopsfm({"-q", "synth", "cylinder", "--video", "--frames", "1",
                                          "--width", "160", "--height", "120", "-o",
                                          scene.string()});
  ASSERT_EQ(synth.exit_code, 0) << synth;
  const fs::path out = dir() / "out";
  const CommandResult run =
      RunLoopsfm({"reconstruct", (scene / "video.mp4").string(), "-o", out.string()});
  ExpectUserError(run);
  EXPECT_TRUE(ContainsRegex(ErrorLine(run), "1 frame: a reconstruction needs at least two"))
      << run;
  // What was extracted is kept.
  EXPECT_EQ(SnapshotDatabase(out / "database.db").frames.size(), 1u);
}

TEST_F(CliBadInputTest, StaticCameraGetsNoModelAndSaysWhy) {
  // Twenty copies of one frame: a camera that never moves.
  const fs::path frames = dir() / "static";
  fs::create_directories(frames);
  const fs::path one = fs::directory_iterator(assets_->good_images)->path();
  for (int i = 0; i < 20; ++i) fs::copy_file(one, frames / fmt::format("f_{:02d}.png", i));
  const fs::path out = dir() / "out";
  const CommandResult run = RunLoopsfm({"reconstruct", frames.string(), "-o", out.string()});
  EXPECT_EQ(run.exit_code, 0) << run;
  EXPECT_TRUE(ContainsRegex(run.output, "no model could be started")) << run;
  EXPECT_TRUE(ContainsRegex(run.output, "stands still")) << run;
  EXPECT_FALSE(fs::exists(out / "sparse" / "0")) << run;
  EXPECT_TRUE(fs::exists(out / "database.db"));
}

TEST_F(CliBadInputTest, PortraitPhoneVideoIsTurnedUpright) {
  // Phones store portrait video as landscape frames with a rotation flag.
  if (!OnPath("ffmpeg")) GTEST_SKIP() << "ffmpeg is not installed (scripts/setup installs it)";
  const fs::path portrait = dir() / "portrait.mp4";
  const CommandResult flag = RunShell(fmt::format(
      "ffmpeg -v error -y -i {} -c copy -metadata:s:v:0 rotate=90 {}",
      ShellQuote(assets_->video.string()), ShellQuote(portrait.string())));
  ASSERT_EQ(flag.exit_code, 0) << flag;
  const fs::path db = dir() / "portrait.db";
  const CommandResult run = RunLoopsfm({"extract", portrait.string(), "-d", db.string()});
  ASSERT_EQ(run.exit_code, 0) << run;
  const std::vector<Camera> cameras = Database::Open(db.string()).ReadCameras();
  ASSERT_EQ(cameras.size(), 1u);
  EXPECT_EQ(cameras[0].width, 120) << "frames were not turned upright";
  EXPECT_EQ(cameras[0].height, 160);
}

TEST_F(CliBadInputTest, OverwriteStartsTheOutputFolderAgain) {
  const fs::path out = dir() / "out";
  fs::create_directories(out);
  fs::copy_file(db_, out / "database.db");
  const std::vector<std::string> args = {"-q", "reconstruct", assets_->good_images.string(), "-o",
                                         out.string(), "--ratio", "0.7", "--export", "none"};
  const CommandResult refused = RunLoopsfm(args);
  ExpectUserError(refused);
  std::vector<std::string> overwrite = args;
  overwrite.push_back("--overwrite");
  const CommandResult again = RunLoopsfm(overwrite);
  ASSERT_EQ(again.exit_code, 0) << again;
  // The new database was made with the new ratio: a rerun with it resumes.
  const CommandResult resumed = RunLoopsfm(args);
  EXPECT_EQ(resumed.exit_code, 0) << resumed;
}

}  // namespace
}  // namespace loopsfm::e2e
