#include <cstdio>

#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/cli/stage_flags.h"
#include "loopsfm/pipeline/export.h"

namespace loopsfm::cli {

void AddExportCommand(CLI::App& app) {
  struct Flags {
    std::string output;
    std::string formats;
    std::string input;
    bool text = false;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* cmd = app.add_subcommand(
      "export", "Write an earlier run's result again, in other formats, without recomputing it");
  cmd->add_option("output", flags->output, "Output folder of `loopsfm reconstruct` (holds sparse/0)")
      ->required();
  cmd->add_option("--format", flags->formats,
                  std::string(kExportFormatsHelp) + "; or all")
      ->required();
  cmd->add_option("--input", flags->input,
                  "The video or image folder the run was made from, when images or gsplat need "
                  "the frames and neither OUT/images nor the recorded source path has them");
  cmd->add_flag("--text", flags->text, "With colmap: also write the models as .txt files");
  cmd->callback([flags] {
    ExportOptions options;
    options.formats = ParseExportFormats(flags->formats);
    if (flags->formats == "all") options.formats.erase(ExportFormat::kReport);
    options.write_text = flags->text;
    std::optional<std::filesystem::path> input;
    if (!flags->input.empty()) input = flags->input;
    const ExportReport report = ExportRun(flags->output, input, options);
    for (const auto& path : report.written) std::printf("wrote %s\n", path.string().c_str());
    std::printf("export: %s\n", report.Counts().c_str());
  });
}

}  // namespace loopsfm::cli
