#include <filesystem>

#include <fmt/format.h>

#include "loopsfm/cli/common.h"
#include "loopsfm/util/errors.h"

namespace loopsfm::cli {

CommonFlags& Common() {
  static CommonFlags flags;  // parsed once by main; read by the subcommand callbacks
  return flags;
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
