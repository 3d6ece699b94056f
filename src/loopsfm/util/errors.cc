#include "loopsfm/util/errors.h"

#include <cstdio>
#include <cstdlib>

namespace loopsfm::internal {

void CheckFailed(const char* file, int line, const char* condition, const std::string& message) {
  std::fprintf(stderr, "loopsfm internal error at %s:%d: check failed: %s%s%s\n", file, line,
               condition, message.empty() ? "" : ": ", message.c_str());
  std::fflush(stderr);
  std::abort();
}

}  // namespace loopsfm::internal
