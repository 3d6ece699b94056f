#include "loopsfm/pipeline/work_sharing.h"

#include <algorithm>
#include <atomic>
#include <optional>
#include <chrono>
#include <exception>
#include <mutex>
#include <thread>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <fmt/ranges.h>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm {
namespace {

// Message tags.
enum Tag : int { kReady = 1, kTask = 2, kResult = 3, kFailed = 4, kStop = 5 };

// Indices finished on worker threads, collected by the main thread.
class DoneList {
 public:
  void Push(size_t index, std::string result = {}) {
    std::lock_guard<std::mutex> lock(mutex_);
    done_.push_back({index, std::move(result), nullptr});
  }
  void PushFailure(size_t index, std::exception_ptr error) {
    std::lock_guard<std::mutex> lock(mutex_);
    done_.push_back({index, {}, error});
  }
  struct Item {
    size_t index;
    std::string result;
    std::exception_ptr error;
  };
  std::vector<Item> Take() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<Item> items;
    items.swap(done_);
    return items;
  }

 private:
  std::mutex mutex_;
  std::vector<Item> done_;
};

// Computations on `threads` threads of their own, started from a thread that goes on handing
// out work and collecting results (it never waits inside the arena). The threads come from
// TBB's pool, made large enough for them unless a caller set a lower limit.
class LocalThreads {
 public:
  explicit LocalThreads(int threads) : arena_(threads, 0) {
    const size_t wanted = size_t(threads) + 1;
    if (tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism) <
        wanted) {
      larger_pool_.emplace(tbb::global_control::max_allowed_parallelism, wanted);
    }
  }
  // Waits for what is still running (after a failure, say).
  ~LocalThreads() {
    WaitBackoff backoff;
    while (running_.load() > 0) backoff.Wait();
  }
  // Runs `compute` for unit `index`; the index (or what it threw) then shows up in Done().
  void Start(size_t index, std::function<void(ByteWriter&)> compute) {
    ++running_;
    arena_.enqueue([this, index, compute = std::move(compute)] {
      ByteWriter result;
      try {
        compute(result);
        done_.Push(index, result.Take());
      } catch (...) {
        done_.PushFailure(index, std::current_exception());
      }
      --running_;
    });
  }
  std::vector<DoneList::Item> Done() { return done_.Take(); }

 private:
  std::optional<tbb::global_control> larger_pool_;
  tbb::task_arena arena_;
  DoneList done_;
  std::atomic<int> running_{0};
};

// One job on rank 0: hands out units to the ranks (this one included) with room for them,
// collects what they computed, and finishes units in order.
class JobRun {
 public:
  JobRun(const WorkSharing::Job& job, Ranks* ranks, int num_threads,
         const std::vector<int>& worker_threads, uint32_t serial)
      : job_(job), ranks_(ranks), serial_(serial), here_(num_threads) {
    const int num_ranks = ranks ? ranks->Size() : 1;
    // Units in flight per rank: one per thread (or per threads_per_unit threads), and one
    // more waiting at each other rank for short units (Job::long_units). A unit that starts
    // threads of its own counts as long.
    const int per_unit = std::max(1, job.threads_per_unit);
    const int waiting = per_unit == 1 && !job.long_units ? 1 : 0;
    capacity_.assign(num_ranks, 0);
    in_flight_.assign(num_ranks, 0);
    units_per_rank_.assign(num_ranks, 0);
    capacity_[0] = std::max(1, num_threads / per_unit);
    for (int rank = 1; rank < num_ranks; ++rank) {
      capacity_[rank] = std::max(1, worker_threads[rank] / per_unit) + waiting;
    }
    int total = 0;
    for (int c : capacity_) total += c;
    // Units done but not yet finished (an earlier one is still out) are held; this bounds
    // them.
    window_ = 4 * static_cast<size_t>(total);
  }

  // Runs the job to its end; `units_per_rank` gets who computed how many.
  void Run(std::vector<size_t>* units_per_rank) {
    WaitBackoff backoff;
    while (true) {
      bool progressed = Collect();
      while (oldest_ < next_ && done_[oldest_]) job_.finish(oldest_++);
      if (no_more_ && oldest_ == next_) break;
      progressed |= HandOut();
      if (progressed) {
        backoff.Reset();
      } else {
        backoff.Wait();
      }
    }
    *units_per_rank = units_per_rank_;
  }

 private:
  // Takes the results that have come, from the other ranks and this rank's threads; true
  // when any had.
  bool Collect() {
    bool any = false;
    while (ranks_) {
      std::optional<RankMessage> message = ranks_->TryReceive();
      if (!message) break;
      any = true;
      if (message->tag == kFailed) {
        throw Error(fmt::format("rank {} failed: {}", message->from, message->bytes));
      }
      if (message->tag != kResult) continue;
      ByteReader reader(message->bytes);
      // A result of an earlier job that failed is dropped.
      if (reader.Get<uint32_t>() != serial_) continue;
      const size_t i = reader.Get<uint64_t>();
      job_.take_result(i, message->from, reader);
      Done(i, message->from);
    }
    for (DoneList::Item& item : here_.Done()) {
      any = true;
      if (item.error) std::rethrow_exception(item.error);
      Done(item.index, 0);
    }
    return any;
  }

  void Done(size_t i, int rank) {
    done_[i] = 1;
    --in_flight_[rank];
    ++units_per_rank_[rank];
  }

  // Hands out the next units while a rank has room; true when any went.
  bool HandOut() {
    bool any = false;
    while (!no_more_ && next_ - oldest_ < window_) {
      const int rank = RankWithMostRoom();
      if (rank < 0) break;
      if (!job_.next(next_)) {
        no_more_ = true;
        break;
      }
      const size_t i = next_++;
      done_.push_back(0);
      any = true;
      if (job_.has_work && !job_.has_work(i)) {
        done_[i] = 1;
      } else if (rank > 0) {
        ByteWriter request;
        request.Put<uint8_t>(static_cast<uint8_t>(job_.kind));
        request.Put<uint32_t>(serial_);
        request.Put<uint64_t>(i);
        job_.request(i, rank, request);
        ranks_->Send(rank, kTask, request.Take());
        ++in_flight_[rank];
      } else {
        ++in_flight_[0];
        here_.Start(i, [this, i](ByteWriter&) { job_.compute(i); });
      }
    }
    return any;
  }

  // The rank with the largest share of its capacity free (the last on ties, so the other
  // ranks start first); -1 when none has room.
  int RankWithMostRoom() const {
    int best = -1;
    double most_free = 0.0;
    for (int r = static_cast<int>(capacity_.size()) - 1; r >= 0; --r) {
      const double free = double(capacity_[r] - in_flight_[r]) / capacity_[r];
      if (free > most_free) {
        best = r;
        most_free = free;
      }
    }
    return best;
  }

  const WorkSharing::Job& job_;
  Ranks* ranks_;
  uint32_t serial_;
  std::vector<int> capacity_, in_flight_;
  std::vector<size_t> units_per_rank_;
  size_t window_ = 0;
  std::vector<char> done_;  // per unit
  size_t next_ = 0, oldest_ = 0;
  bool no_more_ = false;
  // Last: its destructor waits for the units still running here, which use the members.
  LocalThreads here_;
};

}  // namespace

void LogRankShares(const std::string& what, const std::vector<size_t>& per_rank) {
  if (per_rank.size() > 1) spdlog::info("{} per rank: {}", what, fmt::join(per_rank, " / "));
}

int ThreadsPerRank(int requested, const Ranks* ranks) {
  if (requested > 0) return requested;
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int sharing = ranks ? std::max(1, ranks->RanksOnThisMachine()) : 1;
  return std::max(1, cores / sharing);
}

WorkSharing::WorkSharing(Ranks* ranks, int num_threads)
    : ranks_(ranks && ranks->Size() > 1 ? ranks : nullptr),
      num_threads_(ThreadsPerRank(num_threads, ranks)),
      worker_threads_(ranks_ ? ranks_->Size() : 1, 0) {}

WorkSharing::~WorkSharing() { StopWorkers(); }

void WorkSharing::StopWorkers() {
  if (!ranks_ || stopped_) return;
  stopped_ = true;
  for (int rank = 1; rank < ranks_->Size(); ++rank) ranks_->Send(rank, kStop, {});
}

void WorkSharing::AwaitWorkers() {
  if (!ranks_) return;
  while (std::count(worker_threads_.begin() + 1, worker_threads_.end(), 0) > 0) {
    RankMessage message = ranks_->Receive();
    if (message.tag == kFailed) {
      throw Error(fmt::format("rank {} failed: {}", message.from, message.bytes));
    }
    if (message.tag != kReady) {
      throw Error(fmt::format("rank {} sent message {} before saying it was ready",
                              message.from, message.tag));
    }
    ByteReader reader(message.bytes);
    worker_threads_[message.from] = std::max(1, reader.Get<int32_t>());
  }
}

void WorkSharing::Run(const Job& job) {
  if (stopped_) throw Error("the other ranks were already told the run is over");
  AwaitWorkers();
  JobRun(job, ranks_, num_threads_, worker_threads_, ++job_serial_).Run(&units_per_rank_);
}

void ServeWork(Ranks& ranks, const std::map<WorkKind, WorkHandler>& handlers, int num_threads) {
  const int threads = ThreadsPerRank(num_threads, &ranks);
  ByteWriter ready;
  ready.Put<int32_t>(threads);
  ranks.Send(0, kReady, ready.Take());

  LocalThreads here(threads);
  WaitBackoff backoff;
  bool failed = false;
  while (!failed) {
    bool progressed = false;
    std::exception_ptr failure;
    std::optional<RankMessage> message = ranks.TryReceive();
    if (message && message->tag == kStop) break;
    if (message && message->tag == kTask) {
      progressed = true;
      ByteReader reader(message->bytes);
      const auto kind = static_cast<WorkKind>(reader.Get<uint8_t>());
      const auto serial = reader.Get<uint32_t>();
      const size_t index = reader.Get<uint64_t>();
      try {
        auto it = handlers.find(kind);
        if (it == handlers.end()) {
          throw Error(fmt::format("it cannot do work of kind {}", static_cast<int>(kind)));
        }
        std::function<void(ByteWriter&)> compute = it->second(reader);
        here.Start(index, [compute = std::move(compute), serial, index](ByteWriter& result) {
          result.Put<uint32_t>(serial);
          result.Put<uint64_t>(index);
          compute(result);
        });
      } catch (...) {
        failure = std::current_exception();
      }
    }
    std::vector<DoneList::Item> done = here.Done();
    if (failure) done.push_back({0, {}, failure});
    for (DoneList::Item& item : done) {
      progressed = true;
      if (!item.error) {
        ranks.Send(0, kResult, std::move(item.result));
        continue;
      }
      std::string what = "unknown error";
      try {
        std::rethrow_exception(item.error);
      } catch (const std::exception& e) {
        what = e.what();
      } catch (...) {
      }
      ranks.Send(0, kFailed, what);
      failed = true;
    }
    if (progressed) {
      backoff.Reset();
    } else {
      backoff.Wait();
    }
  }
  // After a failure, wait for rank 0 to end the run, so MPI ends cleanly on every rank.
  while (failed) {
    if (ranks.Receive().tag == kStop) break;
  }
}

}  // namespace loopsfm
