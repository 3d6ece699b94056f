#pragma once
// The report's front-end, bundled from web/ (three.js, Chart.js and the report's own
// script) and embedded at build time by cmake/embed_bundle.cmake. Each array ends with a
// zero byte that the size does not count.

#include <cstddef>
#include <string_view>

namespace loopsfm::internal {

extern const unsigned char kReportScript[];
extern const std::size_t kReportScriptSize;
extern const unsigned char kReportStyle[];
extern const std::size_t kReportStyleSize;

inline std::string_view ReportScript() {
  return {reinterpret_cast<const char*>(kReportScript), kReportScriptSize};
}
inline std::string_view ReportStyle() {
  return {reinterpret_cast<const char*>(kReportStyle), kReportStyleSize};
}

}  // namespace loopsfm::internal
