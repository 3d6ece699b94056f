#include <memory>

#include "loopsfm/cli/commands.h"
#include "loopsfm/synth/render.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/progress.h"

namespace loopsfm::cli {

void AddSynthCommand(CLI::App& app) {
  auto options = std::make_shared<SynthOptions>();
  auto output = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand(
      "synth", "Render a synthetic scene with exact ground truth (cylinder | street)");
  cmd->add_option("scene", options->scene, "Scene: cylinder | street")->capture_default_str();
  cmd->add_option("-o,--output", *output, "Output folder")->required();
  cmd->add_option("--frames", options->num_frames, "Number of frames")->capture_default_str();
  cmd->add_option("--width", options->width, "Image width")->capture_default_str();
  cmd->add_option("--height", options->height, "Image height")->capture_default_str();
  cmd->add_flag("--video", options->video, "Write video.mp4 instead of images/");
  cmd->add_option("--seed", options->seed, "Seed of textures and layout")->capture_default_str();
  cmd->callback([options, output] {
    options->Check();
    Progress progress("render", options->num_frames, !Common().quiet);
    const SynthReport report = RenderSyntheticScene(
        *options, *output, [&](int, int) { progress.Advance(); });
    progress.Finish();
    spdlog::info("synth {}: {} frames to {} ({}), ground truth {}, {:.1f} s", options->scene,
                 report.num_frames, report.frames.string(),
                 report.video_codec.empty() ? "png" : report.video_codec,
                 report.groundtruth.string(), report.seconds);
  });
}

}  // namespace loopsfm::cli
