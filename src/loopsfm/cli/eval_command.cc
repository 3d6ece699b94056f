#include <array>
#include <cstdio>
#include <map>

#include <fmt/format.h>

#include "loopsfm/cli/commands.h"
#include "loopsfm/eval/trajectory_metrics.h"
#include "loopsfm/report/top_view.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/util/errors.h"

namespace loopsfm::cli {

namespace {

// A short name for a model in the legend: OUT for OUT/sparse/0, else the file name.
std::string ModelLabel(const std::string& model) {
  std::filesystem::path path = std::filesystem::path(model).lexically_normal();
  if (path.filename().empty()) path = path.parent_path();
  if (path.parent_path().filename() == "sparse") return path.parent_path().parent_path().filename().string();
  return path.filename().string();
}

// Ground truth and each scored model's aligned centres, in ground-truth order; the largest
// loop gap of the first model drawn between its two frames, and the loop links (if any)
// between the first model's frames, one colour per method.
void WritePlot(const std::string& file, const std::vector<TrajectoryEntry>& ground_truth,
               const std::vector<TrajectoryMetrics>& all, const std::vector<std::string>& names,
               const std::vector<LoopLink>& links, const std::string& links_file) {
  const std::array<std::array<unsigned char, 3>, 2> colours = {{{30, 90, 220}, {220, 60, 40}}};
  std::vector<TopViewPath> paths = {{"ground truth", {}, {150, 150, 150}}};
  for (const TrajectoryEntry& e : ground_truth) paths[0].centres.push_back(e.world_from_cam.translation);
  std::vector<TopViewSegments> segments;
  for (size_t m = 0; m < all.size(); ++m) {
    const TrajectoryMetrics& metrics = all[m];
    if (!metrics.aligned) {
      throw InvalidArgument(fmt::format("cannot plot '{}': {}", names[m], metrics.explanation));
    }
    const std::string gap =
        metrics.loop_gaps && metrics.loop_gaps->num_revisits > 0
            ? fmt::format(", loop gap max {:.3g}", metrics.loop_gaps->max)
            : std::string();
    TopViewPath path{fmt::format("{} (ATE {:.3f} % of path{})", ModelLabel(names[m]),
                                 100.0 * metrics.ate_fraction_of_path, gap),
                     {}, colours[m % colours.size()]};
    std::map<std::string, Eigen::Vector3d> aligned;
    for (const FrameError& f : metrics.frames) {
      aligned[f.gt_name] = f.aligned_centre;
      path.centres.push_back(f.aligned_centre);
    }
    paths.push_back(std::move(path));
    if (m == 0 && metrics.loop_gaps && metrics.loop_gaps->num_revisits > 0) {
      const LoopGaps& g = *metrics.loop_gaps;
      if (aligned.count(g.max_first) && aligned.count(g.max_second)) {
        segments.push_back({"largest loop gap: its two frames",
                            {{aligned.at(g.max_first), aligned.at(g.max_second)}},
                            {0, 160, 0}});
      }
    }
    if (m == 0 && !links.empty()) {
      std::map<std::string, Eigen::Vector3d> by_estimated_name;
      for (const FrameError& f : metrics.frames) by_estimated_name[f.estimated_name] = f.aligned_centre;
      std::map<std::string, TopViewSegments> by_method;
      int missing = 0;
      for (const LoopLink& link : links) {
        const auto old_it = by_estimated_name.find(link.old_frame);
        const auto recent_it = by_estimated_name.find(link.recent_frame);
        if (old_it == by_estimated_name.end() || recent_it == by_estimated_name.end()) {
          ++missing;
          continue;
        }
        by_method[link.method].segments.push_back({old_it->second, recent_it->second});
      }
      if (missing == static_cast<int>(links.size())) {
        throw InvalidArgument(fmt::format(
            "none of the {} links of '{}' joins two frames of '{}': pass the loop_links.txt of "
            "the run that wrote this model",
            links.size(), links_file, names[m]));
      }
      for (auto& [method, s] : by_method) {
        s.label = fmt::format("loop links ({}): {}", method, s.segments.size());
        s.rgb = method == "split" ? std::array<unsigned char, 3>{230, 140, 0}
                                  : std::array<unsigned char, 3>{150, 0, 200};
        segments.push_back(std::move(s));
      }
    }
  }
  WriteTopView(file, paths, segments, "top view, aligned to the ground truth");
}

}  // namespace

void AddEvalCommand(CLI::App& app) {
  struct Flags {
    std::string model, groundtruth;
    bool json = false;
    int rpe_step = TrajectoryEvalOptions().rpe_step;
    std::string plot, plot_also, plot_links;
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
  cmd->add_option("--rpe-step", flags->rpe_step,
                  "Relative pose error between ground-truth frames this many apart (0: none). "
                  "It needs no alignment: a step as long as the video gives the drift from end "
                  "to end, which the rotation error cannot show on a straight walk (its "
                  "alignment, fitted to the camera centres, leaves the roll about the line "
                  "undetermined)")
      ->capture_default_str();
  cmd->add_option("--plot", flags->plot,
                  "Also write a top view (PNG) of the ground truth and the model's path aligned "
                  "to it, with the largest loop gap marked");
  cmd->add_option("--plot-also", flags->plot_also,
                  "With --plot: a second model or trajectory drawn in the same view (e.g. the "
                  "same run with --loop-closing none)");
  cmd->add_option("--plot-links", flags->plot_links,
                  "With --plot: draw the frames that loop closing tied together (OUT/"
                  "loop_links.txt of the run that wrote the model) as lines between them")
      ->check(CLI::ExistingFile);
  cmd->callback([flags] {
    if (flags->rpe_step < 0) {
      throw InvalidArgument(fmt::format(
          "--rpe-step must be a number of frames, or 0 for no relative pose error (got {})",
          flags->rpe_step));
    }
    const auto ground_truth = ReadTrajectoryFile(flags->groundtruth);
    if (!flags->plot_also.empty() && flags->plot.empty()) {
      throw InvalidArgument("--plot-also needs --plot FILE.png (the view to draw it in)");
    }
    if (!flags->plot_links.empty() && flags->plot.empty()) {
      throw InvalidArgument("--plot-links needs --plot FILE.png (the view to draw them in)");
    }
    const std::vector<LoopLink> links =
        flags->plot_links.empty() ? std::vector<LoopLink>() : ReadLoopLinksFile(flags->plot_links);
    TrajectoryEvalOptions options;
    options.rpe_step = flags->rpe_step;
    auto evaluate = [&](const std::string& model) {
      return std::filesystem::is_directory(model)
                 ? EvaluateTrajectory(ReadColmapModel(model), ground_truth, options)
                 : EvaluateTrajectory(ReadTrajectoryFile(model), ground_truth, options);
    };
    const TrajectoryMetrics metrics = evaluate(flags->model);
    if (!flags->plot.empty()) {
      std::vector<TrajectoryMetrics> plotted = {metrics};
      std::vector<std::string> names = {flags->model};
      if (!flags->plot_also.empty()) {
        plotted.push_back(evaluate(flags->plot_also));
        names.push_back(flags->plot_also);
      }
      WritePlot(flags->plot, ground_truth, plotted, names, links, flags->plot_links);
    }
    if (flags->json) {
      DeliverReport(ToJson(metrics, true), ToJson(metrics, false).dump(2) + "\n");
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
      if (metrics.alignment_roll_uncertainty_deg > 1e-3 &&
          metrics.alignment_roll_uncertainty_deg >= 0.5 * metrics.rotation_error_mean_deg) {
        out += fmt::format(
            "                    (the centres nearly on a line leave the alignment's roll about "
            "it uncertain by {:.3f} deg, which the rotation error includes; --rpe-step N with a "
            "long step measures the drift without it)\n",
            metrics.alignment_roll_uncertainty_deg);
      }
      if (metrics.rpe && metrics.rpe->num_pairs > 0) {
        const RelativePoseErrors& rpe = *metrics.rpe;
        out += fmt::format(
            "relative pose error {} pairs {} frames apart: translation RMSE {:.6g}, rotation "
            "mean {:.3f} deg, max {:.3f} deg\n",
            rpe.num_pairs, rpe.step, rpe.translation_rmse, rpe.rotation_mean_deg,
            rpe.rotation_max_deg);
      }
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
    DeliverReport(ToJson(metrics, true), out);
  });
}

}  // namespace loopsfm::cli
