#include "loopsfm/pipeline/mpi_ranks.h"

#include <climits>
#include <cstdlib>
#include <list>
#include <string>

#ifdef LOOPSFM_WITH_MPI
#include <mpi.h>
#endif

#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {

int LaunchedProcessCount() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"}) {
    if (const char* value = std::getenv(name)) {
      const int count = std::atoi(value);
      if (count > 0) return count;
    }
  }
  return 1;
}

#ifdef LOOPSFM_WITH_MPI

bool BuiltWithMpi() { return true; }

namespace {

class MpiRanks : public Ranks {
 public:
  MpiRanks() {
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
    MPI_Comm local;
    MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, rank_, MPI_INFO_NULL, &local);
    MPI_Comm_size(local, &local_size_);
    MPI_Comm_free(&local);
  }
  ~MpiRanks() override {
    for (Pending& pending : pending_) MPI_Wait(&pending.request, MPI_STATUS_IGNORE);
    pending_.clear();
    MPI_Finalize();
  }
  int Rank() const override { return rank_; }
  int Size() const override { return size_; }
  int RanksOnThisMachine() const override { return local_size_; }

  void Send(int to, int tag, std::string bytes) override {
    if (bytes.size() > static_cast<size_t>(INT_MAX)) {
      throw Error(fmt::format("a message of {} bytes to rank {} is over MPI's 2 GiB limit",
                              bytes.size(), to));
    }
    // The bytes must live until MPI has sent them: they wait in pending_.
    pending_.push_back({std::move(bytes), MPI_REQUEST_NULL});
    Pending& pending = pending_.back();
    MPI_Isend(pending.bytes.data(), static_cast<int>(pending.bytes.size()), MPI_BYTE, to, tag,
              MPI_COMM_WORLD, &pending.request);
    ReleaseSent();
  }

  std::optional<RankMessage> TryReceive() override {
    ReleaseSent();
    int arrived = 0;
    MPI_Status status;
    MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &arrived, &status);
    if (!arrived) return std::nullopt;
    int count = 0;
    MPI_Get_count(&status, MPI_BYTE, &count);
    RankMessage message{status.MPI_SOURCE, status.MPI_TAG, std::string(size_t(count), '\0')};
    MPI_Recv(message.bytes.data(), count, MPI_BYTE, status.MPI_SOURCE, status.MPI_TAG,
             MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return message;
  }

 private:
  struct Pending {
    std::string bytes;
    MPI_Request request;
  };
  void ReleaseSent() {
    for (auto it = pending_.begin(); it != pending_.end();) {
      int done = 0;
      MPI_Test(&it->request, &done, MPI_STATUS_IGNORE);
      it = done ? pending_.erase(it) : std::next(it);
    }
  }

  int rank_ = 0, size_ = 1, local_size_ = 1;
  std::list<Pending> pending_;
};

}  // namespace

std::unique_ptr<Ranks> StartMpi(int* argc, char*** argv) {
  int provided = 0;
  MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
  if (provided < MPI_THREAD_FUNNELED) {
    MPI_Finalize();
    throw Error("this MPI library cannot run a threaded program (MPI_THREAD_FUNNELED)");
  }
  return std::make_unique<MpiRanks>();
}

#else

bool BuiltWithMpi() { return false; }

std::unique_ptr<Ranks> StartMpi(int*, char***) {
  throw InputError(
      "this loopsfm was built without MPI, so it cannot share a run between processes: "
      "install libopenmpi-dev (scripts/setup does) and build again, or run it without mpirun");
}

#endif

}  // namespace loopsfm
