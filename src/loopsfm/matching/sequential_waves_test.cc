#include "loopsfm/matching/sequential_waves.h"

#include <gtest/gtest.h>

#include <functional>

#include "loopsfm/math/graph.h"

namespace loopsfm {
namespace {

struct WavesRun {
  IndexPairSet tried, verified;
  SequentialWavesReport report;
  int NumComponents() const {
    return ConnectedComponents(verified.NumFrames(), verified.SortedPairs()).NumComponents();
  }
};

// Runs the waves over n frames whose pairs verify when truth(i, j) (i < j) says so.
WavesRun RunWaves(int n, const std::function<bool(int, int)>& truth, const SequentialWavesOptions& options,
             SequentialPairingOptions window = {}) {
  std::vector<image_t> ids(n);
  for (int i = 0; i < n; ++i) ids[i] = 100 + i;
  WavesRun run{IndexPairSet(n), IndexPairSet(n), {}};
  auto verify = [&](const std::vector<ImagePair>& pairs) {
    std::vector<bool> ok;
    for (const ImagePair& p : pairs) {
      const int i = static_cast<int>(p.image_id1) - 100, j = static_cast<int>(p.image_id2) - 100;
      EXPECT_FALSE(run.tried.Contains(i, j)) << "pair tried twice: " << i << ", " << j;
      ok.push_back(truth(std::min(i, j), std::max(i, j)));
    }
    return ok;
  };
  window.num_initial_frames = 0;
  run.report = RunSequentialWaves(ids, window, options, verify, &run.tried, &run.verified);
  return run;
}

TEST(SequentialWaves, WindowGoesPastFailuresAndStopsAfterSeveral) {
  // Pairs up to 3 frames apart verify; frame 30 verifies with nothing (a blurred frame).
  auto truth = [](int i, int j) { return j - i <= 3 && i != 30 && j != 30; };
  SequentialWavesOptions options;
  options.max_quadratic_step = 0;
  const WavesRun run = RunWaves(60, truth, options);
  // Frame 28 goes on past 30 to 31 (verified); 29 reaches 32.
  EXPECT_TRUE(run.verified.Contains(28, 31));
  EXPECT_TRUE(run.verified.Contains(29, 32));
  // A frame in the open tries d = 1..6: three verified, then three failures with d >= 5.
  for (int d = 1; d <= 6; ++d) EXPECT_TRUE(run.tried.Contains(10, 10 + d)) << d;
  EXPECT_FALSE(run.tried.Contains(10, 17));
  // Frame 30 itself tries the minimum window and stops (5 failures, the last 3 past d >= 3).
  for (int d = 1; d <= 5; ++d) EXPECT_TRUE(run.tried.Contains(30, 30 + d)) << d;
  EXPECT_FALSE(run.tried.Contains(30, 36));
  EXPECT_EQ(run.report.num_quadratic_tried, 0u);
}

TEST(SequentialWaves, QuadraticStepsBridgeAnAbruptTurn) {
  // Two stretches of 50 frames; across the turn, frames 40..49 share the corner with frames
  // 14..18 later, like a walker swinging the camera 90 degrees between frames 49 and 50.
  auto truth = [](int i, int j) {
    const bool same_side = (i < 50) == (j < 50);
    if (same_side) return j - i <= 3;
    return i >= 40 && j - i >= 14 && j - i <= 18;
  };
  SequentialWavesOptions options;
  const WavesRun plain = [&] {
    SequentialWavesOptions no_quadratic = options;
    no_quadratic.max_quadratic_step = 0;
    return RunWaves(100, truth, no_quadratic);
  }();
  EXPECT_EQ(plain.NumComponents(), 2);
  const WavesRun run = RunWaves(100, truth, options);
  EXPECT_EQ(run.NumComponents(), 1);
  // i + 16 for i in 40..49 crosses the turn.
  for (int i = 40; i < 50; ++i) EXPECT_TRUE(run.verified.Contains(i, i + 16)) << i;
  EXPECT_GE(run.report.num_quadratic_verified, 10u);
  // Quadratic steps stop after two consecutive failures: 16 and 32 fail for frame 10, so 64
  // is never tried; frames in a stretch with all 16-steps failing try 16 and 32 only.
  EXPECT_TRUE(run.tried.Contains(10, 26));
  EXPECT_TRUE(run.tried.Contains(10, 42));
  EXPECT_FALSE(run.tried.Contains(10, 74));
  EXPECT_LE(run.report.num_quadratic_tried, 2u * 100u);
}

TEST(SequentialWaves, FullWindowWhenEverythingVerifies) {
  auto truth = [](int, int) { return true; };
  SequentialWavesOptions options;
  options.max_quadratic_step = 64;
  SequentialPairingOptions window;
  window.overlap = 4;
  window.initial_overlap = 4;
  const WavesRun run = RunWaves(80, truth, options, window);
  // Every frame: 1..4 and the powers of two beyond: 8, 16, 32, 64.
  for (int d : {1, 2, 3, 4, 8, 16, 32, 64}) EXPECT_TRUE(run.tried.Contains(0, d)) << d;
  EXPECT_FALSE(run.tried.Contains(0, 5));
  EXPECT_FALSE(run.tried.Contains(0, 6));
  size_t expected = 0;
  for (int i = 0; i < 80; ++i) {
    for (int d : {1, 2, 3, 4, 8, 16, 32, 64}) expected += i + d < 80;
  }
  EXPECT_EQ(run.report.num_tried, expected);
  EXPECT_EQ(run.report.num_verified, expected);
}

TEST(SequentialWaves, PairsTriedBeforeAreNotTriedAgain) {
  const int n = 20;
  std::vector<image_t> ids(n);
  for (int i = 0; i < n; ++i) ids[i] = i + 1;
  IndexPairSet tried(n), verified(n);
  tried.Insert(0, 1);  // tried before and failed
  size_t calls = 0;
  auto verify = [&](const std::vector<ImagePair>& pairs) {
    for (const ImagePair& p : pairs) EXPECT_FALSE(p.image_id1 == 1 && p.image_id2 == 2);
    calls += pairs.size();
    return std::vector<bool>(pairs.size(), true);
  };
  const auto report = RunSequentialWaves(ids, {}, {}, verify, &tried, &verified);
  EXPECT_EQ(report.num_tried, calls);
  EXPECT_FALSE(verified.Contains(0, 1));
  EXPECT_TRUE(verified.Contains(0, 2));
}

TEST(SequentialWaves, RejectsBadOptions) {
  SequentialWavesOptions options;
  options.min_window = 0;
  EXPECT_THROW(options.Check(), std::exception);
  options = {};
  options.max_quadratic_step = -1;
  EXPECT_THROW(options.Check(), std::exception);
}

}  // namespace
}  // namespace loopsfm
