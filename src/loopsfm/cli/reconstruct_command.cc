#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/cli/stage_flags.h"
#include "loopsfm/pipeline/reconstruct.h"
#include "loopsfm/util/logging.h"

namespace loopsfm::cli {
namespace {

void PrintSummary(const ReconstructReport& report) {
  std::string out = "\n";
  out += fmt::format("{:<28}{}\n", "frames", report.num_frames);
  for (size_t m = 0; m < report.models.size(); ++m) {
    const ModelSummary& s = report.models[m];
    out += fmt::format("{:<28}{} registered, {} points, track length {:.2f}, reprojection "
                       "error {:.3f} px\n",
                       fmt::format("model {} ({})", m, s.path.string()), s.num_registered,
                       s.num_points, s.mean_track_length, s.mean_reprojection_error);
  }
  if (report.models.empty()) out += fmt::format("{:<28}{}\n", "models", "none");
  for (const StageTime& t : report.stage_times) {
    out += fmt::format("{:<28}{:.1f} s\n", "time " + t.stage, t.seconds);
  }
  const MapperReport& m = report.mapper;
  out += fmt::format("{:<28}registration {:.1f} s, triangulation {:.1f} s, {} local BA {:.1f} s, "
                     "{} global BA {:.1f} s\n",
                     "  of which", m.seconds_registration, m.seconds_triangulation, m.num_local_ba,
                     m.seconds_local_ba, m.num_global_ba, m.seconds_global_ba);
  out += fmt::format("{:<28}{:.1f} s, peak memory {:.0f} MiB\n", "total", report.total_seconds,
                     report.peak_memory_bytes / 1048576.0);
  std::fputs(out.c_str(), stdout);
}

}  // namespace

void AddReconstructCommand(CLI::App& app) {
  struct Flags {
    std::string input, output;
    ExtractFlags extract;
    MatchFlags match;
    bool text = false;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* cmd = app.add_subcommand(
      "reconstruct", "Video or image folder to camera path and sparse point cloud, in one go");
  cmd->add_option("input", flags->input, "Video file (mp4, mov, mkv, avi) or folder of images")
      ->required();
  cmd->add_option("-o,--output", flags->output,
                  "Output folder (database.db, sparse/, points.ply, trajectory.txt); a run "
                  "resumes from what it holds")
      ->required();
  AddExtractFlags(cmd, &flags->extract);
  AddMatchFlags(cmd, &flags->match);
  cmd->add_flag("--text", flags->text, "Also write the COLMAP model as .txt files");
  cmd->callback([flags] {
    ReconstructOptions options;
    options.extract = flags->extract.Resolve();
    options.match = flags->match.Resolve();
    options.mapper.num_threads = Common().threads;
    options.write_text = flags->text;
    options.show_progress = !Common().quiet;
    const ReconstructReport report = Reconstruct(flags->input, flags->output, options);
    PrintSummary(report);
  });
}

}  // namespace loopsfm::cli
