// loopsfm: camera path and sparse 3D structure from video.

#include <cstdio>
#include <algorithm>
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
  CLI::App app{"loopsfm: camera poses and a sparse point cloud from video, with loop closing"};
  app.require_subcommand(1);
  // --threads, -v and -q work after the subcommand too (`loopsfm reconstruct ... -q`).
  app.fallthrough();
  app.set_version_flag("--version", fmt::format("loopsfm 0.1.0 (memory allocator: {}; MPI: {})",
                                                AllocatorName(),
                                                BuiltWithMpi() ? "yes" : "no, one process"));
  auto& common = cli::Common();
  app.add_option("--threads", common.threads,
                 "Worker threads (0: all cores); under mpirun, per process (0: the machine's "
                 "cores shared between the processes on it)")
      ->capture_default_str();
  app.add_flag("-v,--verbose", common.verbose, "More log output");
  app.add_flag("-q,--quiet", common.quiet, "Only warnings and errors");
  app.parse_complete_callback([&] {
    SetupLogging(common.quiet ? Verbosity::kQuiet
                              : common.verbose ? Verbosity::kVerbose : Verbosity::kNormal);
    // Ceres logs through glog (to the terminal, never to log files): its warnings (a linear
    // solve that failed and was retried with more damping) are the solver's own business and
    // show only with -v; its errors always do.
    FLAGS_minloglevel = common.verbose ? google::GLOG_WARNING : google::GLOG_ERROR;
    if (sharing) {
      common.sharing = &*sharing;
      spdlog::info("MPI: {} ranks share extraction, matching and segments", ranks->Size());
    }
  });

  cli::AddReconstructCommand(app);
  cli::AddEvalCommand(app);
  cli::AddExportCommand(app);
  cli::AddExtractCommand(app);
  cli::AddMatchCommand(app);
  cli::AddTracksCommand(app);
  cli::AddSynthCommand(app);
  cli::AddVocabCommand(app);

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
