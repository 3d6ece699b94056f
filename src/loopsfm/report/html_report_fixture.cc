// Writes the HTML report of a finished `loopsfm reconstruct` run from what the run left
// behind, for the browser test (web/test/report_browser_test.sh):
//
//   html_report_fixture RUN_DIR GROUNDTRUTH RECONSTRUCT_LOG REPORT_HTML
//
// RUN_DIR holds database.db, sparse/0.. and the matrix plots (database_similarity.png,
// database_matches.png); GROUNDTRUTH is a trajectory file ("-" for none); RECONSTRUCT_LOG
// is the run's output, whose summary lines give the time per stage and the peak memory.
#include <filesystem>
#include <fstream>
#include <iostream>
#include <regex>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "loopsfm/eval/trajectory_metrics.h"
#include "loopsfm/report/html_report.h"
#include "loopsfm/report/report_data.h"
#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/util/errors.h"

namespace fs = std::filesystem;
using namespace loopsfm;

namespace {

// "time extract   3.9 s" lines and "total  9.7 s, peak memory 226 MiB" of the run's summary.
void AddTimes(const fs::path& log, nlohmann::json& data) {
  std::ifstream in(log);
  if (!in) throw InputError(fmt::format("cannot read the run's log '{}'", log.string()));
  const std::regex stage(R"(^time (\S.*\S)\s+([0-9.]+) s\s*$)");
  const std::regex total(R"(^total\s+([0-9.]+) s, peak memory ([0-9.]+) MiB)");
  data["stages"] = nlohmann::json::array();
  std::smatch m;
  for (std::string line; std::getline(in, line);) {
    if (std::regex_search(line, m, stage)) {
      data["stages"].push_back({{"name", m[1].str()}, {"seconds", std::stod(m[2].str())}});
    } else if (std::regex_search(line, m, total)) {
      data["summary"]["total_seconds"] = std::stod(m[1].str());
      data["summary"]["peak_memory_mib"] = std::stod(m[2].str());
    }
  }
}

// Ground truth and the first model's centres aligned to it, seen from above; the errors.
void AddGroundTruth(const fs::path& groundtruth, const Reconstruction& model, nlohmann::json& data) {
  const std::vector<TrajectoryEntry> truth = ReadTrajectoryFile(groundtruth);
  const TrajectoryMetrics metrics = EvaluateTrajectory(model, truth);
  if (!metrics.aligned) throw InputError("cannot align the model to the ground truth: " + metrics.explanation);
  std::vector<Eigen::Vector3d> true_centres, aligned;
  for (const TrajectoryEntry& e : truth) true_centres.push_back(e.world_from_cam.translation);
  for (const FrameError& f : metrics.frames) aligned.push_back(f.aligned_centre);
  const TopViewPlane plane = FitTopViewPlane(true_centres);
  data["top_view"] = {{"x_label", "first principal axis"}, {"y_label", "second principal axis"},
                      {"paths", {ReportTopViewPath("ground truth", true_centres, plane),
                                 ReportTopViewPath("loopsfm", aligned, plane)}}};
  data["evaluation"] = {{"ate_fraction_of_path", metrics.ate_fraction_of_path},
                        {"ate_rmse", metrics.ate_rmse},
                        {"rotation_error_mean_deg", metrics.rotation_error_mean_deg}};
  if (metrics.loop_gaps && metrics.loop_gaps->num_revisits > 0) {
    data["evaluation"]["loop_gap_max"] = metrics.loop_gaps->max;
    data["evaluation"]["loop_gap_mean"] = metrics.loop_gaps->mean;
  }
}

nlohmann::json BuildReport(const fs::path& run, const std::string& groundtruth, const fs::path& log) {
  if (!fs::exists(run / "database.db")) throw InputError(fmt::format("no database.db in '{}'", run.string()));
  const std::vector<Frame> frames = Database::Open((run / "database.db").string()).ReadFrames();
  std::vector<Reconstruction> models;
  for (int k = 0; fs::exists(run / "sparse" / std::to_string(k)); ++k) {
    models.push_back(ReadColmapModel(run / "sparse" / std::to_string(k)));
  }
  if (models.empty()) throw InputError(fmt::format("no model in '{}'", (run / "sparse").string()));

  nlohmann::json data;
  data["title"] = fmt::format("loopsfm: {}", run.filename().string());
  data["output"] = run.string();
  size_t registered = 0;
  for (const Reconstruction& model : models) registered += model.NumRegImages();
  Reconstruction first = models[0];
  data["summary"] = {{"frames", frames.size()}, {"registered", registered}, {"models", models.size()},
                     {"points", first.NumPoints3D()},
                     {"mean_track_length", first.ComputeMeanTrackLength()},
                     {"reprojection_error_px", first.UpdateReprojectionErrors()}};
  AddTimes(log, data);
  data["cameras"] = ReportCameras(first);
  data["frames"] = ReportFrames(frames, models);
  data["points"] = ReportPoints(first);
  data["matrices"] = nlohmann::json::array();
  for (const auto& [title, file] : {std::pair{"Similarity (vocabulary tree)", "database_similarity.png"},
                                    std::pair{"Verified matches", "database_matches.png"}}) {
    if (fs::exists(run / file)) data["matrices"].push_back(ReportImage(title, run / file));
  }
  if (groundtruth != "-") AddGroundTruth(groundtruth, first, data);
  return data;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 5) {
    std::cerr << "usage: html_report_fixture RUN_DIR GROUNDTRUTH|- RECONSTRUCT_LOG REPORT_HTML\n";
    return 2;
  }
  try {
    WriteHtmlReport(argv[4], BuildReport(argv[1], argv[2], argv[3]));
  } catch (const Error& e) {
    std::cerr << "html_report_fixture: " << e.what() << "\n";
    return 2;
  }
  std::cout << "wrote " << argv[4] << "\n";
  return 0;
}
