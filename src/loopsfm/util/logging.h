#pragma once
// Logging through spdlog. Library code logs with spdlog::info/warn/debug; the CLI picks
// the level from --verbose / --quiet.

#include <spdlog/spdlog.h>

namespace loopsfm {

enum class Verbosity { kQuiet, kNormal, kVerbose };

// Sends log lines to stderr with a short "[level] message" pattern, at the given level; may be
// called again to change the level.
void SetupLogging(Verbosity verbosity);

}  // namespace loopsfm
