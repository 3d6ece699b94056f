// loopsfm: camera poses and a sparse 3D point cloud from video.

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <glog/logging.h>
#ifdef LOOPSFM_WITH_MIMALLOC
#include <mimalloc.h>
#endif

#include "loopsfm/cli/app.h"
#include "loopsfm/cli/commands.h"
#include "loopsfm/pipeline/mpi_ranks.h"
#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace {

// The allocator that serves malloc in this process: mimalloc where the build linked it and it
// does stand in for the C library's malloc (linked ahead of libc), else the C library's.
std::string AllocatorName() {
#ifdef LOOPSFM_WITH_MIMALLOC
  void* probe = std::malloc(64);
  const bool mimalloc_serves = mi_is_in_heap_region(probe);
  std::free(probe);
  if (mimalloc_serves) {
    const int version = mi_version();  // 209 for 2.0.9
    return fmt::format("mimalloc {}.{}.{}", version / 100, version / 10 % 10, version % 10);
  }
#endif
  return "the C library's malloc";
}

// The value of --threads in the command line (0 when absent), for ranks that serve rank 0
// and do not run the command.
int ThreadsFlag(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--threads" && i + 1 < argc) return std::max(0, std::atoi(argv[i + 1]));
    if (arg.rfind("--threads=", 0) == 0) return std::max(0, std::atoi(arg.c_str() + 10));
  }
  return 0;
}

// Ctrl-C: the first asks the run to stop at its next step (what is stored stays, and the
// same command goes on from there); a second one ends the program at once.
std::atomic<bool> stop_requested{false};

void OnInterrupt(int) {
  if (stop_requested.exchange(true)) {
    std::signal(SIGINT, SIG_DFL);
    std::raise(SIGINT);
    return;
  }
  constexpr char kMessage[] =
      "\nloopsfm: stopping at the next step (Ctrl-C again to stop at once)\n";
  [[maybe_unused]] const auto written = write(2, kMessage, sizeof(kMessage) - 1);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace loopsfm;
  // Started by mpirun or srun with several processes: rank 0 runs the command, the other
  // ranks compute what it shares out (extraction, matching) until it is done.
  std::unique_ptr<Ranks> ranks;
  if (LaunchedProcessCount() > 1) {
    try {
      ranks = StartMpi(&argc, &argv);
    } catch (const Error& e) {
      std::fprintf(stderr, "loopsfm: error: %s\n", e.what());
      return 2;
    }
    if (ranks->Rank() > 0) {
      SetupLogging(Verbosity::kQuiet);
      try {
        ServeStageWork(*ranks, ThreadsFlag(argc, argv));
      } catch (const std::exception& e) {
        std::fprintf(stderr, "loopsfm: rank %d: %s\n", ranks->Rank(), e.what());
        return 1;
      }
      return 0;
    }
  }
  // Made before the command line is parsed, so the other ranks are told the run is over
  // (when it ends, fails, or the command line is wrong) before MPI ends.
  std::optional<WorkSharing> sharing;
  if (ranks) sharing.emplace(ranks.get(), ThreadsFlag(argc, argv));
  FLAGS_logtostderr = true;
  FLAGS_minloglevel = google::GLOG_ERROR;
  google::InitGoogleLogging(argv[0]);
  // Under MPI, mpirun passes Ctrl-C on to every rank, and the ranks end together.
  RunHooks hooks;
  if (!ranks) {
    std::signal(SIGINT, OnInterrupt);
    hooks.stop_requested = [] { return stop_requested.load(); };
    cli::Common().hooks = &hooks;
  }
  CLI::App app;
  cli::AddCommands(app, sharing ? &*sharing : nullptr, AllocatorName());

  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  } catch (const Cancelled& e) {
    std::fprintf(stderr, "loopsfm: stopped: %s\n", e.what());
    return 130;
  } catch (const Error& e) {
    std::fprintf(stderr, "loopsfm: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "loopsfm: unexpected error: %s\n", e.what());
    return 1;
  }
  return 0;
}
