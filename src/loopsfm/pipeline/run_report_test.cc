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

// The global mapper's warnings reach the summary, with the figures the log gave; a run without
// any (or by the incremental mapper) has none.
TEST(RunReport, GlobalMapperWarningsInTheSummary) {
  ReconstructReport report;
  EXPECT_FALSE(DataOf(report)["summary"].contains("warnings"));
  report.global_mapper = GlobalMapperReport{};
  EXPECT_FALSE(DataOf(report)["summary"].contains("warnings"));

  report.global_mapper->num_bent_components = 1;
  report.global_mapper->positioning.num_observations = 1000;
  report.global_mapper->positioning.num_large_angle_observations = 187;
  nlohmann::json data = DataOf(report);
  ASSERT_EQ(data["summary"]["warnings"].size(), 1u);
  const std::string bent = data["summary"]["warnings"][0];
  EXPECT_NE(bent.find("1 component likely bent"), std::string::npos) << bent;
  EXPECT_NE(bent.find("18.7 % more than 2 deg"), std::string::npos) << bent;

  report.global_mapper->num_broken_models = 2;
  report.global_mapper->largest_step_ratio = 80.0;
  report.global_mapper->largest_step_from = "0054.jpg";
  report.global_mapper->largest_step_to = "0068.jpg";
  data = DataOf(report);
  ASSERT_EQ(data["summary"]["warnings"].size(), 2u);
  const std::string broken = data["summary"]["warnings"][1];
  EXPECT_NE(broken.find("2 models likely broken"), std::string::npos) << broken;
  EXPECT_NE(broken.find("80x the median, 0054.jpg to 0068.jpg"), std::string::npos) << broken;
}

}  // namespace
}  // namespace loopsfm
