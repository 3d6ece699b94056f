// The layer rule of DESIGN.md, checked on the #include lines of every source file:
// a module includes only modules of a strictly lower layer (tests may include anything).

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <string>

namespace {

const std::map<std::string, int> kLayers = {
    {"util", 0},      {"math", 1},      {"geometry", 2},   {"sensor", 2},   {"robust", 3},
    {"scene", 3},     {"storage", 4},   {"video", 4},      {"feature", 4},  {"retrieval", 4},
    {"synth", 4},     {"eval", 4},      {"matching", 5},   {"tracks", 5},   {"estimators", 5},
    {"sfm", 6},       {"loop", 7},      {"report", 7},     {"pipeline", 8}, {"cli", 9},
};

TEST(Layering, IncludesGoOnlyDown) {
  namespace fs = std::filesystem;
  const fs::path root = fs::path(LOOPSFM_SOURCE_DIR) / "src" / "loopsfm";
  const std::regex include_re(R"(#include\s+"loopsfm/([a-z_]+)/)");
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(root)) {
    const auto ext = entry.path().extension();
    if (ext != ".h" && ext != ".cc") continue;
    const std::string module = fs::relative(entry.path(), root).begin()->string();
    ASSERT_TRUE(kLayers.count(module)) << "module '" << module << "' has no layer: "
                                       << entry.path();
    const bool is_test = entry.path().filename().string().ends_with("_test.cc");
    std::ifstream in(entry.path());
    std::string line;
    ++files;
    while (std::getline(in, line)) {
      std::smatch m;
      if (!std::regex_search(line, m, include_re)) continue;
      const std::string other = m[1];
      ASSERT_TRUE(kLayers.count(other)) << entry.path() << " includes unknown module " << other;
      if (other == module || is_test) continue;
      EXPECT_LT(kLayers.at(other), kLayers.at(module))
          << entry.path() << " (" << module << ", layer " << kLayers.at(module) << ") includes "
          << other << " (layer " << kLayers.at(other) << ")";
    }
  }
  EXPECT_GT(files, 10);
}

}  // namespace
