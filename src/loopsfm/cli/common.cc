#include <cstdio>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

#include "loopsfm/cli/common.h"
#include "loopsfm/util/errors.h"

namespace loopsfm::cli {

CommonFlags& Common() {
  static CommonFlags flags;  // parsed once by main; read by the subcommand callbacks
  return flags;
}

void DeliverReport(const nlohmann::json& report, const std::string& text) {
  if (Common().report) {
    *Common().report = report;
  } else if (!text.empty()) {
    std::fputs(text.c_str(), stdout);
  }
}

void WriteJsonReport(const std::string& path, const nlohmann::json& report) {
  std::ofstream out(path);
  out << report.dump(2) << "\n";
  if (!out) throw StorageError(fmt::format("cannot write '{}'", path));
}

Database OpenExistingDatabase(const std::string& path) {
  if (!std::filesystem::exists(path)) {
    throw InputError(fmt::format(
        "database '{}' does not exist; create it with `loopsfm extract INPUT -d {}` first", path,
        path));
  }
  return Database::Open(path);
}

}  // namespace loopsfm::cli
