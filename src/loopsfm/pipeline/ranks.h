#pragma once
// The processes of one run and the messages between them. Under `mpirun -np N` (or `srun`)
// they are MPI ranks (mpi_ranks.h); in one process, threads stand in for them
// (InProcessRanks), so every distributed path also runs, and is tested, without MPI.
// Rank 0 runs the pipeline and writes every file; the other ranks compute what it sends
// them (work_sharing.h).

#include <algorithm>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace loopsfm {

struct RankMessage {
  int from = 0;
  int tag = 0;
  std::string bytes;
};

class Ranks {
 public:
  virtual ~Ranks() = default;
  virtual int Rank() const = 0;
  virtual int Size() const = 0;
  // How many of the ranks run on this rank's machine (they share its cores).
  virtual int RanksOnThisMachine() const = 0;
  // Sends without waiting for the receiver; messages from one rank to another arrive in the
  // order they were sent.
  virtual void Send(int to, int tag, std::string bytes) = 0;
  // The next message that has arrived, from any rank; nullopt when none has.
  virtual std::optional<RankMessage> TryReceive() = 0;
  // Waits for the next message, sleeping between looks (a waiting rank leaves its cores to
  // the ranks and threads that compute).
  RankMessage Receive();
};

// Sleeps a little longer each time nothing happened, from microseconds (a result is due) to
// a millisecond: a waiting rank leaves its cores to the threads that compute.
class WaitBackoff {
 public:
  void Reset() { pause_ = std::chrono::microseconds(20); }
  void Wait() {
    std::this_thread::sleep_for(pause_);
    pause_ = std::min(pause_ * 2, std::chrono::microseconds(1000));
  }

 private:
  std::chrono::microseconds pause_{20};
};

// `size` endpoints of one in-process group: endpoint r is rank r. Each may be used from one
// thread at a time.
std::vector<std::unique_ptr<Ranks>> InProcessRanks(int size);

}  // namespace loopsfm
