#pragma once
// Flags shared by all subcommands and helpers the commands share.

#include <string>

#include <nlohmann/json.hpp>

#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/util/progress.h"

namespace loopsfm::cli {

struct CommonFlags {
  // Worker threads (0: all cores).
  int threads = 0;
  bool verbose = false;
  bool quiet = false;
  // The other ranks of an MPI run, which extraction and matching share their work with
  // (null: this process alone).
  WorkSharing* sharing = nullptr;
  // Who follows the run's progress and may stop it (Ctrl-C in the program; the Python
  // module's callback and KeyboardInterrupt); null: nobody.
  const RunHooks* hooks = nullptr;
  // Where a command run in-process (RunCommand, app.h) puts its report; null: the program,
  // which prints it.
  nlohmann::json* report = nullptr;
};
// The global flags, parsed before any subcommand callback runs.
CommonFlags& Common();

// Hands a command's report to whoever ran it: RunCommand's caller gets `report`; the program
// prints `text` to stdout (nothing when empty).
void DeliverReport(const nlohmann::json& report, const std::string& text);

// Writes a stage's report as JSON (--json-report); StorageError when it cannot.
void WriteJsonReport(const std::string& path, const nlohmann::json& report);

// Opens a database that a previous stage created; InputError naming the stage to run when
// it does not exist (instead of silently creating an empty one).
Database OpenExistingDatabase(const std::string& path);

}  // namespace loopsfm::cli
