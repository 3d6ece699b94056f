// Extraction and matching shared between ranks write the database one process writes: the
// ranks here are threads (InProcessRanks) serving with the stages' own handlers, as the
// ranks of an MPI run do (tests/e2e/cli_mpi_e2e_test.cc runs them under mpirun).

#include <gtest/gtest.h>

#include <thread>

#include <tbb/global_control.h>

#include "loopsfm/pipeline/extract.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/synth/render.h"
#include "loopsfm/synth/synth_test_util.h"

namespace loopsfm {
namespace {

// What the stages stored, byte for byte.
std::string Contents(const Database& database) {
  ByteWriter w;
  for (const Camera& camera : database.ReadCameras()) w.PutVector(camera.params);
  for (const Frame& frame : database.ReadFrames()) {
    w.Put(frame.image_id);
    w.Put(frame.camera_id);
    w.PutString(frame.name);
    const FeatureSet features = database.ReadFeatures(frame.image_id);
    w.PutVector(features.keypoints);
    w.PutBytes(features.descriptors.data(), features.descriptors.size());
  }
  for (const auto& [pair, geometry] : database.ReadAllTwoViewGeometries()) {
    w.Put(pair);
    w.Put(geometry.config);
    w.PutVector(geometry.inlier_matches);
    w.PutBytes(geometry.F.data(), 9 * sizeof(double));
    w.PutBytes(geometry.E.data(), 9 * sizeof(double));
    w.PutBytes(geometry.H.data(), 9 * sizeof(double));
    w.PutVector(database.ReadMatches(pair.image_id1, pair.image_id2));
  }
  return w.Take();
}

// Extracts and matches the frames in `images` into `database_path`, sharing the work with
// `num_ranks - 1` other ranks.
void ExtractAndMatch(const std::filesystem::path& images, const std::string& database_path,
                     int num_ranks, std::vector<size_t>* units_per_rank) {
  tbb::global_control pool(tbb::global_control::max_allowed_parallelism, 16);
  auto ranks = InProcessRanks(num_ranks);
  std::vector<std::thread> workers;
  for (int r = 1; r < num_ranks; ++r) {
    workers.emplace_back([&ranks, r] { ServeStageWork(*ranks[r], 1); });
  }
  {
    WorkSharing sharing(ranks[0].get(), 1);
    Database database = Database::Open(database_path);
    ExtractOptions extract;
    extract.keyframes.mode = KeyframeMode::kWindows;
    extract.sharing = &sharing;
    extract.show_progress = false;
    ExtractFeatures(images, database, extract);
    MatchOptions match;
    match.strategy = PairStrategy::kExhaustive;
    match.sharing = &sharing;
    match.show_progress = false;
    match.batch_size = 16;  // several batches, so frames are dropped and sent again
    MatchPairs(database, match);
    *units_per_rank = sharing.UnitsPerRank();
  }
  for (std::thread& worker : workers) worker.join();
}

TEST(SharedStages, DatabasesFromOneTwoAndFourRanksAreTheSame) {
  synth_test::TempDir dir("shared_stages");
  SynthOptions synth = synth_test::SmallOptions("cylinder");
  synth.num_frames = 16;
  RenderSyntheticScene(synth, dir.path() / "scene");
  std::string contents_alone;
  for (int num_ranks : {1, 2, 4}) {
    const std::string path = (dir.path() / fmt::format("ranks{}.db", num_ranks)).string();
    std::vector<size_t> units;
    ExtractAndMatch(dir.path() / "scene" / "images", path, num_ranks, &units);
    const std::string contents = Contents(Database::Open(path));
    ASSERT_GT(contents.size(), 16u * 1000u);
    if (num_ranks == 1) {
      contents_alone = contents;
      continue;
    }
    EXPECT_TRUE(contents == contents_alone) << num_ranks << " ranks wrote another database";
    // Other ranks took part (the first units go to the last rank).
    ASSERT_EQ(units.size(), size_t(num_ranks));
    EXPECT_GT(units.back(), 0u);
  }
}

}  // namespace
}  // namespace loopsfm
