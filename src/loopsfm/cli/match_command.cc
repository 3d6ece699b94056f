#include <fstream>

#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/cli/stage_flags.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm::cli {
namespace {

void LogTrackReport(const TrackBuildReport& report) {
  std::string histogram;
  for (const auto& [length, count] : report.length_histogram) {
    histogram += fmt::format(" {}:{}", length, count);
  }
  spdlog::info("tracks: {} (mean length {:.2f}), {} conflicting split ({} matches left out); "
               "length histogram{}",
               report.num_tracks, report.mean_track_length, report.num_conflicting_tracks,
               report.num_dropped_matches, histogram);
}

}  // namespace

void AddMatchCommand(CLI::App& app) {
  struct Flags {
    std::string database;
    std::string json_report;
    MatchFlags match;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* cmd =
      app.add_subcommand("match", "Match frame pairs and verify their two-view geometry");
  cmd->add_option("-d,--database", flags->database, "Database written by `loopsfm extract`")
      ->required();
  AddMatchFlags(cmd, &flags->match);
  cmd->add_option("--json-report", flags->json_report,
                  "Also write the stage report (pairs tried and verified, timings) as JSON");
  cmd->callback([flags] {
    Database database = OpenExistingDatabase(flags->database);
    const MatchOptions options = flags->match.Resolve();
    const MatchReport report = MatchPairs(database, options);
    spdlog::info(
        "match ({}, {} kernel): {} pairs ({} already stored), {} matched now, {} verified, "
        "{:.0f} mean inliers; median {:.1f} ms matching + {:.1f} ms verification per pair; "
        "{:.1f} s",
        PairStrategyName(options.strategy), report.kernel, report.num_pairs, report.num_pairs_resumed,
        report.num_pairs_matched, report.num_pairs_verified, report.MeanInliers(),
        report.median_match_ms, report.median_verify_ms, report.seconds);
    LogRankShares("match: pairs", report.pairs_per_rank);
    if (!flags->json_report.empty()) WriteJsonReport(flags->json_report, ToJson(report));
    TrackBuildReport tracks;
    BuildTracksFromDatabase(database, {}, &tracks);
    LogTrackReport(tracks);
    DeliverReport(ToJson(report), "");
  });
}

void AddTracksCommand(CLI::App& app) {
  auto database_path = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand("tracks", "Build tracks from the verified matches and report");
  cmd->add_option("-d,--database", *database_path, "Database with verified matches")->required();
  cmd->callback([database_path] {
    Database database = OpenExistingDatabase(*database_path);
    TrackBuildReport report;
    BuildTracksFromDatabase(database, {}, &report);
    LogTrackReport(report);
  });
}

}  // namespace loopsfm::cli
