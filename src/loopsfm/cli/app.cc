#include "loopsfm/cli/app.h"

#include <algorithm>
#include <cstdlib>
#include <mutex>

#include <fmt/format.h>
#include <glog/logging.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/pipeline/mpi_ranks.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm::cli {
namespace {

constexpr const char* kDescription =
    "loopsfm: camera poses and a sparse point cloud from video, with loop closing";

// What serves malloc where loopsfm runs in another program (the Python module).
constexpr const char* kLibcMalloc = "the C library's malloc";

// RunCommand and HelpText bind the flags to Common(): one at a time.
std::mutex& CommandMutex() {
  static std::mutex mutex;
  return mutex;
}

}  // namespace

std::string VersionText(const std::string& allocator) {
  return fmt::format("loopsfm {} (memory allocator: {}; MPI: {})", LOOPSFM_VERSION, allocator,
                     BuiltWithMpi() ? "yes" : "no, one process");
}

void AddCommands(CLI::App& app, WorkSharing* sharing, const std::string& allocator) {
  app.description(kDescription);
  // Not the path the program was started by: help reads the same everywhere (docs/cli.md).
  app.name("loopsfm");
  app.require_subcommand(1);
  // --threads, -v and -q work after the subcommand too (`loopsfm reconstruct ... -q`).
  app.fallthrough();
  app.set_version_flag("--version", VersionText(allocator));
  CommonFlags& common = Common();
  app.add_option("--threads", common.threads,
                 "Worker threads (0: all cores); under mpirun, per process (0: the machine's "
                 "cores shared between the processes on it)")
      ->capture_default_str();
  app.add_flag("-v,--verbose", common.verbose, "More log output");
  app.add_flag("-q,--quiet", common.quiet, "Only warnings and errors");
  app.parse_complete_callback([&common, sharing] {
    SetupLogging(common.quiet ? Verbosity::kQuiet
                              : common.verbose ? Verbosity::kVerbose : Verbosity::kNormal);
    // Ceres logs through glog (to the terminal, never to log files): its warnings (a linear
    // solve that failed and was retried with more damping) are the solver's own business and
    // show only with -v; its errors always do.
    FLAGS_minloglevel = common.verbose ? google::GLOG_WARNING : google::GLOG_ERROR;
    if (sharing) {
      common.sharing = sharing;
      spdlog::info("MPI: {} ranks share extraction, matching and segments", sharing->NumRanks());
    }
  });

  AddReconstructCommand(app);
  AddEvalCommand(app);
  AddExportCommand(app);
  AddExtractCommand(app);
  AddMatchCommand(app);
  AddMapCommand(app);
  AddTracksCommand(app);
  AddSynthCommand(app);
  AddVocabCommand(app);
}

nlohmann::json RunCommand(const std::vector<std::string>& args, const RunHooks* hooks) {
  std::lock_guard<std::mutex> lock(CommandMutex());
  // The global flags point at this call's hooks and report: reset however the call ends.
  struct ResetCommon {
    ~ResetCommon() { Common() = CommonFlags(); }
  } reset;
  Common() = CommonFlags();
  CLI::App app;
  AddCommands(app, nullptr, kLibcMalloc);
  nlohmann::json report;
  Common().hooks = hooks;
  Common().report = &report;
  // CLI11 takes the arguments last first.
  std::vector<std::string> reversed(args.rbegin(), args.rend());
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    throw InvalidArgument(e.what());
  }
  return report;
}

std::string HelpText(const std::string& subcommand) {
  std::lock_guard<std::mutex> lock(CommandMutex());
  Common() = CommonFlags();
  CLI::App app;
  AddCommands(app, nullptr, kLibcMalloc);
  if (subcommand.empty()) return app.help();
  const auto subcommands = app.get_subcommands({});
  const bool known = std::any_of(subcommands.begin(), subcommands.end(),
                                 [&](const CLI::App* s) { return s->get_name() == subcommand; });
  if (!known) {
    throw InvalidArgument(fmt::format("'{}' is not a loopsfm command; see the list in the "
                                      "program's help",
                                      subcommand));
  }
  return app.get_subcommand(subcommand)->help(app.get_name());
}

}  // namespace loopsfm::cli
