#include "loopsfm/cli/commands.h"
#include "loopsfm/cli/stage_flags.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"
#include "loopsfm/video/frame_source.h"

namespace loopsfm::cli {

void AddExtractCommand(CLI::App& app) {
  struct Flags {
    std::string input, database, json_report;
    ExtractFlags extract;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* cmd = app.add_subcommand(
      "extract", "Decode frames, pick keyframes, extract SIFT features into a database");
  cmd->add_option("input", flags->input, "Video file (mp4, mov, mkv, avi) or folder of images")
      ->required();
  cmd->add_option("-d,--database", flags->database, "Database file (created if missing)")
      ->required();
  AddExtractFlags(cmd, &flags->extract);
  cmd->add_option("--json-report", flags->json_report,
                  "Also write the stage report (frames, features, timings) as JSON");
  cmd->callback([flags] {
    const ExtractOptions options = flags->extract.Resolve();
    // Refuse a bad input before the database file is created.
    OpenFrameSource(flags->input);
    Database database = Database::Open(flags->database);
    const ExtractReport report = ExtractFeatures(flags->input, database, options);
    spdlog::info(
        "extract: {} frames ({} new, {} already stored), {} unreadable skipped, {} camera(s), "
        "{:.0f} features/frame, {:.1f} frames/s, {:.1f} s, peak memory {:.0f} MiB",
        report.frames_decoded, report.frames_extracted, report.frames_resumed,
        report.unreadable_images, report.num_cameras, report.FeaturesPerFrame(),
        report.FramesPerSecond(), report.seconds, PeakResidentBytes() / (1024.0 * 1024.0));
    LogRankShares("extract: frames", report.frames_per_rank);
    if (!flags->json_report.empty()) WriteJsonReport(flags->json_report, ToJson(report));
    DeliverReport(ToJson(report), "");
  });
}

}  // namespace loopsfm::cli
