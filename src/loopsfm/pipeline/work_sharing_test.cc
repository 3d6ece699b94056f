#include "loopsfm/pipeline/work_sharing.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include <tbb/global_control.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Ranks 1.. of an in-process group, each serving with its own handler, on threads.
class Workers {
 public:
  Workers(std::vector<std::unique_ptr<Ranks>>& ranks,
          const std::vector<WorkHandler>& handlers)
      // The ranks share one process here, and so TBB's pool: room for each rank's threads.
      : pool_(tbb::global_control::max_allowed_parallelism, 16) {
    for (size_t r = 1; r < ranks.size(); ++r) {
      threads_.emplace_back([&ranks, handler = handlers[r - 1], r] {
        ServeWork(*ranks[r], {{WorkKind::kMatchPairs, handler}}, 1);
      });
    }
  }
  ~Workers() {
    for (std::thread& thread : threads_) thread.join();
  }

 private:
  tbb::global_control pool_;
  std::vector<std::thread> threads_;
};

// Squares the number in the request, taking `pause` to do it.
WorkHandler Squarer(std::chrono::microseconds pause) {
  return [pause](ByteReader& request) {
    const auto value = request.Get<int64_t>();
    return [value, pause](ByteWriter& result) {
      std::this_thread::sleep_for(pause);
      result.Put<int64_t>(value * value);
    };
  };
}

// A job squaring 0..n-1, here or on other ranks; records the order units finish in.
struct SquaresJob {
  explicit SquaresJob(size_t n, std::chrono::microseconds pause = {}) : squares(n, -1) {
    job.kind = WorkKind::kMatchPairs;
    job.next = [n](size_t i) { return i < n; };
    job.compute = [this, pause](size_t i) {
      std::this_thread::sleep_for(pause);
      squares[i] = int64_t(i) * int64_t(i);
    };
    job.request = [](size_t i, int, ByteWriter& request) { request.Put<int64_t>(int64_t(i)); };
    job.take_result = [this](size_t i, int, ByteReader& result) {
      squares[i] = result.Get<int64_t>();
    };
    job.finish = [this](size_t i) { finished.push_back(i); };
  }
  WorkSharing::Job job;
  std::vector<int64_t> squares;
  std::vector<size_t> finished;
};

TEST(WorkSharing, AloneComputesEveryUnitHereInOrder) {
  WorkSharing sharing(nullptr, 3);
  SquaresJob squares(100);
  sharing.Run(squares.job);
  for (size_t i = 0; i < 100; ++i) {
    EXPECT_EQ(squares.squares[i], int64_t(i * i));
    EXPECT_EQ(squares.finished[i], i);
  }
  EXPECT_EQ(sharing.UnitsPerRank(), std::vector<size_t>{100});
}

TEST(WorkSharing, EveryRankTakesUnitsAndTheyFinishInOrder) {
  auto ranks = InProcessRanks(3);
  const auto pause = std::chrono::microseconds(300);
  Workers workers(ranks, {Squarer(pause), Squarer(pause)});
  WorkSharing sharing(ranks[0].get(), 1);
  for (int run = 0; run < 2; ++run) {  // the ranks serve one job after another
    SquaresJob squares(200, pause);
    sharing.Run(squares.job);
    for (size_t i = 0; i < 200; ++i) {
      ASSERT_EQ(squares.squares[i], int64_t(i * i));
      ASSERT_EQ(squares.finished[i], i);
    }
    size_t total = 0;
    for (size_t units : sharing.UnitsPerRank()) {
      EXPECT_GT(units, 0u);
      total += units;
    }
    EXPECT_EQ(total, 200u);
  }
  sharing.StopWorkers();
}

// Shares follow the cost: a rank ten times slower than another takes fewer units.
TEST(WorkSharing, ASlowRankTakesFewerUnits) {
  auto ranks = InProcessRanks(3);
  Workers workers(ranks, {Squarer(std::chrono::microseconds(5000)),
                          Squarer(std::chrono::microseconds(500))});
  WorkSharing sharing(ranks[0].get(), 1);
  SquaresJob squares(300, std::chrono::microseconds(500));
  sharing.Run(squares.job);
  const std::vector<size_t>& units = sharing.UnitsPerRank();
  EXPECT_LT(2 * units[1], units[2]) << units[0] << " " << units[1] << " " << units[2];
}

// Three units, each 10x longer on rank 1 than here. Short units queue one more at rank 1,
// which then holds two while this rank idles; long units (segments) go where a thread is free,
// so this rank, done with its first, takes the third.
TEST(WorkSharing, LongUnitsWaitForAFreeRankInsteadOfQueueingAtABusyOne) {
  for (const bool long_units : {false, true}) {
    SCOPED_TRACE(long_units ? "long units" : "short units");
    auto ranks = InProcessRanks(2);
    Workers workers(ranks, {Squarer(std::chrono::milliseconds(600))});
    WorkSharing sharing(ranks[0].get(), 1);
    SquaresJob squares(3, std::chrono::milliseconds(60));
    squares.job.long_units = long_units;
    sharing.Run(squares.job);
    sharing.StopWorkers();
    for (size_t i = 0; i < 3; ++i) EXPECT_EQ(squares.squares[i], int64_t(i * i));
    EXPECT_EQ(sharing.UnitsPerRank(), (std::vector<size_t>{long_units ? 2u : 1u, long_units ? 1u : 2u}));
  }
}

TEST(WorkSharing, UnitsWithoutWorkGoStraightToFinish) {
  auto ranks = InProcessRanks(2);
  Workers workers(ranks, {Squarer({})});
  WorkSharing sharing(ranks[0].get(), 1);
  SquaresJob squares(50);
  squares.job.has_work = [](size_t i) { return i % 2 == 0; };
  sharing.Run(squares.job);
  ASSERT_EQ(squares.finished.size(), 50u);
  for (size_t i = 0; i < 50; ++i) {
    EXPECT_EQ(squares.finished[i], i);
    EXPECT_EQ(squares.squares[i], i % 2 == 0 ? int64_t(i * i) : -1);
  }
  EXPECT_EQ(sharing.UnitsPerRank()[0] + sharing.UnitsPerRank()[1], 25u);
}

TEST(WorkSharing, AUnitThatFailsOnAnotherRankFailsTheRunWithItsMessage) {
  auto ranks = InProcessRanks(2);
  WorkHandler failing = [](ByteReader&) -> std::function<void(ByteWriter&)> {
    return [](ByteWriter&) { throw InputError("frame 7 is unreadable"); };
  };
  Workers workers(ranks, {failing});
  WorkSharing sharing(ranks[0].get(), 1);
  SquaresJob squares(20, std::chrono::microseconds(2000));
  try {
    sharing.Run(squares.job);
    FAIL() << "the run did not fail";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("rank 1 failed: frame 7 is unreadable"),
              std::string::npos)
        << e.what();
  }
}

TEST(WorkSharing, AUnitThatFailsHereFailsTheRun) {
  WorkSharing sharing(nullptr, 2);
  SquaresJob squares(20);
  squares.job.compute = [](size_t i) {
    if (i == 5) throw InputError("unit 5");
  };
  EXPECT_THROW(sharing.Run(squares.job), InputError);
}

TEST(WorkSharing, ThreadsPerRankShareTheMachine) {
  EXPECT_EQ(ThreadsPerRank(3, nullptr), 3);
  auto ranks = InProcessRanks(64);
  EXPECT_EQ(ThreadsPerRank(0, ranks[0].get()), 1);
  EXPECT_GE(ThreadsPerRank(0, nullptr), 1);
}

}  // namespace
}  // namespace loopsfm
