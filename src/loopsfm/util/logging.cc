#include "loopsfm/util/logging.h"

#include <spdlog/sinks/stdout_color_sinks.h>

namespace loopsfm {

void SetupLogging(Verbosity verbosity) {
  // Made once; a process that runs several commands (the Python module) sets its level again.
  auto logger = spdlog::get("loopsfm");
  if (!logger) {
    logger = spdlog::stderr_color_mt("loopsfm");
    logger->set_pattern("[%^%l%$] %v");
  }
  switch (verbosity) {
    case Verbosity::kQuiet: logger->set_level(spdlog::level::warn); break;
    case Verbosity::kNormal: logger->set_level(spdlog::level::info); break;
    case Verbosity::kVerbose: logger->set_level(spdlog::level::debug); break;
  }
  spdlog::set_default_logger(logger);
}

}  // namespace loopsfm
