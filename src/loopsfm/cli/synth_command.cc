#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/synth/render.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/progress.h"

namespace loopsfm::cli {
namespace {

// A frame-range flag, parsed once the command line is complete.
struct RangeFlag {
  CLI::Option* option = nullptr;
  std::string spec;
};

struct SynthRangeFlags {
  RangeFlag blur;
  RangeFlag low_texture;
  RangeFlag dark;
};

// Parses the flag's spec with `parse` into `out` when the flag was given; errors name the flag.
template <typename T, typename Parse>
void ParseRangeFlag(const RangeFlag& flag, Parse&& parse, std::vector<T>* out) {
  if (flag.option->count() == 0) return;
  try {
    *out = parse(flag.spec);
  } catch (const InvalidArgument& e) {
    throw InvalidArgument(fmt::format("{}: {}", flag.option->get_name(), e.what()));
  }
}

}  // namespace

void AddSynthCommand(CLI::App& app) {
  auto options = std::make_shared<SynthOptions>();
  auto output = std::make_shared<std::string>();
  auto ranges = std::make_shared<SynthRangeFlags>();
  auto camera_model = std::make_shared<std::string>("PINHOLE");
  CLI::App* cmd = app.add_subcommand(
      "synth", "Render a synthetic scene with exact ground truth (cylinder | street)");
  cmd->add_option("scene", options->scene, "Scene: cylinder | street")->capture_default_str();
  cmd->add_option("-o,--output", *output, "Output folder")->required();
  cmd->add_option("--frames", options->num_frames, "Number of frames")->capture_default_str();
  cmd->add_option("--width", options->width, "Image width")->capture_default_str();
  cmd->add_option("--height", options->height, "Image height")->capture_default_str();
  cmd->add_option("--focal-factor", options->focal_length_factor,
                  "Focal length as a multiple of the image width (0.9: a 58 degree field across "
                  "the width; 0.45: 96 degrees, an action camera)")
      ->capture_default_str();
  cmd->add_flag("--video", options->video, "Write video.mp4 instead of images/");
  cmd->add_option("--seed", options->seed, "Seed of textures, layout, shake and noise")
      ->capture_default_str();

  // The lens.
  cmd->add_option("--camera-model", *camera_model,
                  "Lens: COLMAP camera model of the frames, with its distortion coefficients "
                  "below (" + CameraModelNameList() + ")")
      ->capture_default_str();
  LensOptions& lens = options->lens;
  const std::pair<const char*, double*> coefficients[] = {
      {"--k1", &lens.k1}, {"--k2", &lens.k2}, {"--k3", &lens.k3}, {"--k4", &lens.k4},
      {"--k5", &lens.k5}, {"--k6", &lens.k6}, {"--p1", &lens.p1}, {"--p2", &lens.p2}};
  for (const auto& [flag, value] : coefficients) {
    const std::string_view name = flag + 2;
    std::vector<std::string_view> models;  // those whose parameters name it (k1 is also "k")
    for (const CameraModelId id : kCameraModelIds) {
      for (const std::string_view param : CameraModelParamNames(id)) {
        if (param == name || (param == "k" && name == "k1")) models.push_back(CameraModelName(id));
      }
    }
    cmd->add_option(flag, *value,
                    fmt::format("Lens: distortion coefficient {}, for {}", name,
                                fmt::join(models, ", ")))
        ->capture_default_str();
  }

  // The street walk.
  cmd->add_option("--route", options->street_route,
                  "Street: block (around one block) | figure8 (around two blocks) | avenue "
                  "(straight along a row of blocks, never coming back; --laps and --revisit set "
                  "its length, in loops around a block) | pan (standing still, the view turns "
                  "120 degrees on the spot: no baseline)")
      ->capture_default_str();
  cmd->add_option("--laps", options->street_laps, "Street: full laps of the route")
      ->capture_default_str();
  cmd->add_flag("--repeated-facades", options->street_repeated_facades,
                "Street: identical buildings (one size, one texture) around each block, so "
                "places far apart look the same");
  cmd->add_option("--revisit", options->street_revisit_fraction,
                  "Street: fraction of the route walked again after the laps")
      ->capture_default_str();
  cmd->add_option("--look-ahead", options->street_look_ahead_degrees,
                  "Street: degrees the view turns from the facade towards the walking direction")
      ->capture_default_str();
  cmd->add_flag("--abrupt-turns", options->street_abrupt_turns,
                "Street: the view jumps between two frames at each corner, by 90 degrees (by "
                "90 - 2 x look-ahead where the figure-eight passes to the other block); needs "
                "--look-ahead 20 or more");
  cmd->add_option("--shake", options->shake_degrees,
                  "Hand-held shake: std. dev. of a smooth random rotation per axis, degrees")
      ->capture_default_str();
  cmd->add_option("--jitter", options->shake_centimeters,
                  "Hand-held shake: std. dev. of a smooth random offset per axis, cm")
      ->capture_default_str();

  // Degradations of the rendered frames.
  FrameDegradationOptions& degradation = options->degradation;
  cmd->add_option("--noise", degradation.noise_sigma,
                  "Gaussian sensor noise, std. dev. in grey levels")
      ->capture_default_str();
  ranges->blur.option = cmd->add_option("--blur", ranges->blur.spec,
                  "Motion blur along the image motion: FIRST-LAST:PIXELS[,...], e.g. "
                  "120-140:15,300-310:25");
  ranges->low_texture.option = cmd->add_option("--low-texture", ranges->low_texture.spec,
                  "Frames washed out towards flat grey: FIRST-LAST[,...], e.g. 400-430");
  cmd->add_option("--low-texture-contrast", degradation.low_texture_contrast,
                  "Contrast left in --low-texture frames (0..1)")
      ->capture_default_str();
  ranges->dark.option =
      cmd->add_option("--dark", ranges->dark.spec, "Black frames (before noise): FIRST-LAST[,...]");
  cmd->add_option("--jpeg-quality", degradation.jpeg_quality,
                  "JPEG quality 1-100: images as .jpg; video frames JPEG-compressed before "
                  "H.264 (whose quality OpenCV fixes at CRF 23); 0: off")
      ->capture_default_str();

  cmd->callback([options, output, ranges, camera_model] {
    try {
      options->lens.model = ParseCameraModel(*camera_model);
    } catch (const InvalidArgument& e) {
      throw InvalidArgument(fmt::format("--camera-model: {}", e.what()));
    }
    FrameDegradationOptions& degradation = options->degradation;
    ParseRangeFlag(ranges->blur, ParseBlurRanges, &degradation.motion_blur);
    ParseRangeFlag(ranges->low_texture, ParseFrameRanges, &degradation.low_texture);
    ParseRangeFlag(ranges->dark, ParseFrameRanges, &degradation.dark);
    options->Check();
    Progress progress("render", options->num_frames, !Common().quiet);
    const SynthReport report = RenderSyntheticScene(
        *options, *output, [&](int, int) { progress.Advance(); });
    progress.Finish();
    const bool jpeg = degradation.jpeg_quality > 0;
    spdlog::info("synth {}: {} frames to {} ({}{}), ground truth {}, {:.1f} s", options->scene,
                 report.num_frames, report.frames.string(),
                 report.video_codec.empty() ? (jpeg ? "jpg" : "png") : report.video_codec,
                 report.video_codec.empty() || !jpeg ? "" : " after JPEG",
                 report.groundtruth.string(), report.seconds);
  });
}

}  // namespace loopsfm::cli
