#pragma once
// Sharing a stage's work between the ranks of a run (ranks.h). Rank 0 runs the stage and
// hands out its units of work (a frame to extract, a few pairs to match) to its own threads
// and to the other ranks, each taking the next unit as it becomes free: a faster rank or
// machine takes more, so the shares follow the measured cost, not the count. Results come
// back to rank 0, which alone writes them, in unit order, so the database does not depend on
// which rank computed what. With no other ranks the same code runs on this rank's threads.

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "loopsfm/pipeline/ranks.h"
#include "loopsfm/util/byte_io.h"

namespace loopsfm {

// The kinds of work a rank can be sent.
enum class WorkKind : uint8_t { kExtractSift = 1, kMatchPairs = 2, kMapSegment = 3 };

class WorkSharing {
 public:
  // `ranks`: the run's ranks, this being rank 0 (null: this process alone). `num_threads`:
  // this rank's threads for units (0: its share of the machine's cores).
  WorkSharing(Ranks* ranks, int num_threads);
  // Tells the other ranks that the run is over.
  ~WorkSharing();
  WorkSharing(const WorkSharing&) = delete;
  WorkSharing& operator=(const WorkSharing&) = delete;

  struct Job {
    WorkKind kind;
    // Threads one unit keeps busy: 1 for a unit computed on the thread it is given; more for
    // one that starts threads of its own (a segment's mapper), so a rank of T threads takes
    // T / threads_per_unit such units at once.
    int threads_per_unit = 1;
    // Units long enough (a segment to map) that one waiting at a busy rank could have
    // started on a rank that has come free: no rank is handed more than it starts at once.
    // Short ones (a frame, a batch of pairs) get one more waiting at each other rank, so that
    // rank never idles between a result and its next request.
    bool long_units = false;
    // Makes unit i ready, on this thread, i = 0, 1, ... in turn; false when there is none.
    std::function<bool(size_t i)> next;
    // Whether unit i has anything to compute (a frame extracted before has not); when not,
    // it goes straight to `finish`. Null: every unit has.
    std::function<bool(size_t i)> has_work;
    // Computes unit i on one of this rank's threads (units run at once).
    std::function<void(size_t i)> compute;
    // The request that makes rank `rank` compute unit i, and what to do with its result (on
    // this thread).
    std::function<void(size_t i, int rank, ByteWriter& request)> request;
    std::function<void(size_t i, int rank, ByteReader& result)> take_result;
    // Unit i is done: called on this thread in unit order.
    std::function<void(size_t i)> finish;
  };
  // Runs a job to its end. Throws what a unit threw here, or Error with another rank's
  // message when a unit failed there.
  void Run(const Job& job);

  int NumRanks() const { return ranks_ ? ranks_->Size() : 1; }
  int NumThreads() const { return num_threads_; }
  // Units each rank computed in the last Run, rank 0 first.
  const std::vector<size_t>& UnitsPerRank() const { return units_per_rank_; }
  // Tells the other ranks that the run is over (they return from ServeWork).
  void StopWorkers();

 private:
  void AwaitWorkers();

  Ranks* ranks_;
  int num_threads_;
  std::vector<int> worker_threads_;  // per rank; 0 until the rank said it is ready
  std::vector<size_t> units_per_rank_;
  uint32_t job_serial_ = 0;  // tells the results of one Run from those of an earlier one
  bool stopped_ = false;
};

// A worker rank's handler for one kind of work: reads a request on the rank's main thread
// (keeping what it needs between requests, such as features already sent) and returns the
// computation, which runs on one of the rank's threads and writes the result.
using WorkHandler = std::function<std::function<void(ByteWriter& result)>(ByteReader& request)>;

// The other ranks' part: computes what rank 0 sends until it says stop. `num_threads`: 0 for
// this rank's share of the machine's cores.
void ServeWork(Ranks& ranks, const std::map<WorkKind, WorkHandler>& handlers, int num_threads);

// ServeWork with the handlers of every stage that shares work (extraction, matching, segment
// mapping).
void ServeStageWork(Ranks& ranks, int num_threads);

// Logs how the units of a stage were shared between the ranks of an MPI run ("extract: frames
// per rank: 40 / 38 / 41"); nothing in one process.
void LogRankShares(const std::string& what, const std::vector<size_t>& per_rank);

// Threads for one rank: `requested` when positive, else the machine's cores shared between
// the ranks on it.
int ThreadsPerRank(int requested, const Ranks* ranks);

}  // namespace loopsfm
