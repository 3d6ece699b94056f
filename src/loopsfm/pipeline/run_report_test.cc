#include "loopsfm/pipeline/run_report.h"

#include <gtest/gtest.h>

namespace loopsfm {
namespace {
namespace fs = std::filesystem;

nlohmann::json DataOf(const ReconstructReport& report) {
  return RunReportData(report, {}, {}, "video.mp4", fs::path(::testing::TempDir()) / "run_report",
                       std::nullopt);
}

TEST(RunReport, TimelineAsIndexLists) {
  ReconstructReport report;
  report.timeline.frames_read = 12;
  report.timeline.kept = {{0, "first"}, {5, "parallax"}, {7, "fill-in"}, {11, ""}};
  report.timeline.blurred = {3, 7};
  report.timeline.localized = {1, 2, 9};
  const nlohmann::json data = DataOf(report);
  ASSERT_TRUE(data.contains("timeline"));
  EXPECT_EQ(data["timeline"], nlohmann::json::parse(R"({
    "frames_read": 12,
    "kept": [[0, "first"], [5, "parallax"], [7, "fill-in"], [11, ""]],
    "blurred": [3, 7],
    "localized": [1, 2, 9]})"));
}

TEST(RunReport, NoTimelineWithoutFramesRead) {
  EXPECT_FALSE(DataOf(ReconstructReport{}).contains("timeline"));
}

}  // namespace
}  // namespace loopsfm
