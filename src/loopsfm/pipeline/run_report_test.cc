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
  EXPECT_NE(broken.find("map with --mapper incremental"), std::string::npos) << broken;
  EXPECT_EQ(data["summary"]["mapper"], "global");

  // Handed to the incremental mapper: the warnings say so instead of advising it.
  report.global_mapper_set_aside = MapperReport{};
  data = DataOf(report);
  ASSERT_EQ(data["summary"]["warnings"].size(), 2u);
  for (const std::string warning : data["summary"]["warnings"]) {
    EXPECT_EQ(warning.find("map with --mapper incremental"), std::string::npos) << warning;
    EXPECT_NE(warning.find("the incremental mapper mapped the video instead"), std::string::npos)
        << warning;
  }
  EXPECT_NE(data["summary"]["mapper"].get<std::string>().find("incremental"), std::string::npos);
}

// Segments the global mapper doubted and the incremental mapper mapped again are named.
TEST(RunReport, SegmentsHandedToTheIncrementalMapperInTheSummary) {
  ReconstructReport report;
  report.segments = SegmentMappingReport{};
  report.segments->global = true;
  report.segments->segments.resize(3);
  report.segments->segments[1].first_frame = 40;
  report.segments->segments[1].num_frames = 50;
  EXPECT_FALSE(DataOf(report)["summary"].contains("warnings"));
  report.segments->segments[1].global_set_aside = true;
  const nlohmann::json data = DataOf(report);
  ASSERT_EQ(data["summary"]["warnings"].size(), 1u);
  const std::string warning = data["summary"]["warnings"][0];
  EXPECT_NE(warning.find("segment 1 (frames 40-89)"), std::string::npos) << warning;
}

}  // namespace
}  // namespace loopsfm
