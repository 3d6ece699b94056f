#include <cstdio>

#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/eval/trajectory_metrics.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/storage/colmap_model.h"

namespace loopsfm::cli {

void AddEvalCommand(CLI::App& app) {
  struct Flags {
    std::string model, groundtruth;
    bool json = false;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* cmd = app.add_subcommand(
      "eval", "Score a model (COLMAP folder or trajectory file) against ground truth");
  cmd->add_option("model", flags->model,
                  "COLMAP model folder (bin or txt, e.g. OUT/sparse/0) or a trajectory file")
      ->required();
  cmd->add_option("groundtruth", flags->groundtruth,
                  "Ground truth: 'name tx ty tz qx qy qz qw' per line, camera-to-world")
      ->required();
  cmd->add_flag("--json", flags->json, "Print the metrics as JSON");
  cmd->callback([flags] {
    const auto ground_truth = ReadTrajectoryFile(flags->groundtruth);
    const TrajectoryMetrics metrics =
        std::filesystem::is_directory(flags->model)
            ? EvaluateTrajectory(ReadColmapModel(flags->model), ground_truth)
            : EvaluateTrajectory(ReadTrajectoryFile(flags->model), ground_truth);
    if (flags->json) {
      std::puts(ToJson(metrics, false).dump(2).c_str());
      return;
    }
    std::string out;
    out += fmt::format("frames registered   {} / {} ({:.1f} %)\n", metrics.num_matched,
                       metrics.num_gt_frames, 100.0 * metrics.fraction_registered);
    if (!metrics.aligned) {
      out += fmt::format("not aligned: {}\n", metrics.explanation);
    } else {
      out += fmt::format("ATE RMSE            {:.6g} (ground-truth units)\n", metrics.ate_rmse);
      out += fmt::format("ATE / path length   {:.4f} % of {:.6g}\n",
                         100.0 * metrics.ate_fraction_of_path, metrics.gt_path_length);
      out += fmt::format("rotation error      mean {:.3f} deg, max {:.3f} deg\n",
                         metrics.rotation_error_mean_deg, metrics.rotation_error_max_deg);
      const LoopGaps& gaps = *metrics.loop_gaps;
      if (gaps.num_revisits == 0) {
        out += fmt::format(
            "loop gap            no revisits (no two frames {}+ apart within {:.3g} of each "
            "other)\n",
            gaps.min_frame_gap, gaps.max_distance);
      } else {
        out += fmt::format(
            "loop gap            mean {:.4g}, median {:.4g}, max {:.4g} ({} + {}) over {} "
            "revisits\n",
            gaps.mean, gaps.median, gaps.max, gaps.max_first, gaps.max_second,
            gaps.num_revisits);
      }
    }
    std::fputs(out.c_str(), stdout);
  });
}

}  // namespace loopsfm::cli
