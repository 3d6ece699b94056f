#include "loopsfm/report/html_report.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;

constexpr const char* kDataStart = "window.LOOPSFM_REPORT = ";
constexpr const char* kDataEnd = ";\n</script>";

fs::path FreshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("loopsfm_html_report_test_" + name + "_" +
                                                    std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string ReadText(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

size_t CountCaseInsensitive(std::string text, const std::string& needle) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  size_t count = 0;
  for (size_t at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) ++count;
  return count;
}

// The JSON between "window.LOOPSFM_REPORT = " and the end of its script tag.
nlohmann::json EmbeddedData(const std::string& html) {
  const size_t begin = html.find(kDataStart);
  EXPECT_NE(begin, std::string::npos);
  const size_t start = begin + std::string(kDataStart).size();
  const size_t end = html.find(kDataEnd, start);
  EXPECT_NE(end, std::string::npos);
  return nlohmann::json::parse(html.substr(start, end - start));
}

nlohmann::json ExampleData() {
  return {{"title", "loopsfm: block.mp4"},
          {"summary", {{"frames", 3}, {"registered", 2}, {"points", 4}}},
          {"stages", {{{"name", "extract"}, {"seconds", 2.5}}, {{"name", "map"}, {"seconds", 7.0}}}},
          {"frames",
           {{{"index", 0}, {"name", "frame_000000.png"}, {"registered", true},
             {"center", {0.0, 0.0, 0.0}}, {"world_from_cam_rotation", {1, 0, 0, 0, 1, 0, 0, 0, 1}}},
            {{"index", 1}, {"name", "frame_000001.png"}, {"registered", false}}}},
          {"points", {{"xyz", {0.5, 0.25, 3.0}}, {"rgb", {255, 128, 0}}}}};
}

TEST(HtmlReportTest, WritesOneDocumentWithTheDataStyleAndScript) {
  const fs::path file = FreshDir("writes") / "report.html";
  const nlohmann::json data = ExampleData();
  WriteHtmlReport(file, data);
  const std::string html = ReadText(file);
  EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_EQ(EmbeddedData(html), data);
  // The embedded front-end: three.js, Chart.js and the report's script (several hundred kB),
  // and its stylesheet; nothing is loaded from elsewhere.
  EXPECT_GT(html.size(), 200000u);
  EXPECT_NE(html.find("loopsfmReport"), std::string::npos);
  EXPECT_NE(html.find("selected-camera"), std::string::npos);
  EXPECT_NE(html.find(".view3d"), std::string::npos);
  EXPECT_EQ(CountCaseInsensitive(html, "<script"), 2u);
  EXPECT_EQ(CountCaseInsensitive(html, "</script"), 2u);
  EXPECT_EQ(CountCaseInsensitive(html, "<link"), 0u);
  EXPECT_EQ(CountCaseInsensitive(html, "<script src"), 0u);
  EXPECT_EQ(HtmlReport(data), html);
}

TEST(HtmlReportTest, StringsInTheDataCannotEndTheScriptTag) {
  nlohmann::json data = ExampleData();
  data["title"] = "</script><script>alert(1)</script><!-- <SCRIPT>";
  data["frames"][0]["name"] = "</ScRiPt>";
  const std::string html = HtmlReport(data);
  EXPECT_EQ(CountCaseInsensitive(html, "</script"), 2u);
  EXPECT_EQ(CountCaseInsensitive(html, "<script"), 2u);
  const size_t start = html.find(kDataStart);
  const std::string raw = html.substr(start, html.find(kDataEnd, start) - start);
  EXPECT_EQ(raw.find('<'), std::string::npos) << raw;
  EXPECT_EQ(EmbeddedData(html), data);
}

TEST(HtmlReportTest, InvalidUtf8IsReplacedNotFatal) {
  nlohmann::json data = ExampleData();
  data["input"] = std::string("video\xff\xfe.mp4");
  const nlohmann::json embedded = EmbeddedData(HtmlReport(data));
  EXPECT_EQ(embedded["input"], "video\xEF\xBF\xBD\xEF\xBF\xBD.mp4");
  EXPECT_EQ(embedded["summary"], data["summary"]);
}

TEST(HtmlReportTest, EmptyDataStillMakesADocument) {
  const std::string html = HtmlReport(nlohmann::json::object());
  EXPECT_EQ(EmbeddedData(html), nlohmann::json::object());
  EXPECT_NE(html.find("</html>"), std::string::npos);
}

TEST(HtmlReportTest, UnwritableFileThrowsStorageErrorNamingIt) {
  const fs::path file = FreshDir("unwritable") / "missing_folder" / "report.html";
  try {
    WriteHtmlReport(file, ExampleData());
    FAIL() << "expected StorageError";
  } catch (const StorageError& e) {
    EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(file));
}

}  // namespace
}  // namespace loopsfm
