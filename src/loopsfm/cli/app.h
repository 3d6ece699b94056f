#pragma once
// The loopsfm command line as a library: the program (main.cc) and the Python module
// (python/) take the same flags, with the same defaults, checks and messages.

#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/util/progress.h"

namespace loopsfm::cli {

// "loopsfm 0.1.0 (memory allocator: ALLOCATOR; MPI: ...)", what --version prints.
std::string VersionText(const std::string& allocator);

// Adds --version, the global flags (--threads, -v, -q) and every subcommand to `app`.
// `sharing`: the other ranks of an MPI run that extraction, matching and segments are shared
// with (null: this process alone); it must outlive the parse. `allocator` names what serves
// malloc in this process, for --version.
void AddCommands(CLI::App& app, WorkSharing* sharing, const std::string& allocator);

// Runs one command line (without the program's name, e.g. {"reconstruct", "clip.mp4", "-o",
// "out"}) in this process, as the program would, except that the command's report comes back
// as JSON (null for commands without one) instead of being printed, and `hooks` (may be null)
// follow the progress and may stop the run. One command runs at a time in a process: a
// second caller waits. Throws what the program turns into messages and exit codes:
// loopsfm::Error (InvalidArgument for a command line CLI11 refuses), Cancelled. Its
// --version names the C library's malloc.
nlohmann::json RunCommand(const std::vector<std::string>& args, const RunHooks* hooks);

// The help text of a subcommand ("" for the program's own), as `--help` prints it.
std::string HelpText(const std::string& subcommand);

}  // namespace loopsfm::cli
