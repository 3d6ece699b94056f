// ReconstructReport as JSON, for callers that run loopsfm in-process (the Python module).

#include "loopsfm/pipeline/mapper_checkpoint.h"
#include "loopsfm/pipeline/reconstruct.h"

namespace loopsfm {
namespace {

nlohmann::json ToJson(const ModelSummary& model) {
  nlohmann::json cameras = nlohmann::json::array();
  for (const Camera& camera : model.cameras) {
    cameras.push_back({{"camera_id", camera.camera_id},
                       {"model", camera.ModelName()},
                       {"width", camera.width},
                       {"height", camera.height},
                       {"params", camera.params}});
  }
  return {{"path", model.path.string()},
          {"num_registered", model.num_registered},
          {"num_points", model.num_points},
          {"mean_track_length", model.mean_track_length},
          {"mean_reprojection_error", model.mean_reprojection_error},
          {"cameras", cameras}};
}

nlohmann::json ToJson(const SelfCalibrationReport& report) {
  nlohmann::json cameras = nlohmann::json::array();
  for (const CameraSelfCalibration& c : report.cameras) {
    cameras.push_back({{"camera_id", c.camera_id},
                       {"applied", c.applied},
                       {"initial_focal_px", c.initial_focal_px},
                       {"focal_px", c.focal_px},
                       {"k1", c.k1},
                       {"explanation", c.estimate.explanation}});
  }
  return {{"cameras", cameras}, {"seconds", report.seconds}};
}

}  // namespace

nlohmann::json ToJson(const ReconstructReport& report) {
  nlohmann::json models = nlohmann::json::array();
  for (const ModelSummary& model : report.output.models) models.push_back(ToJson(model));
  nlohmann::json written = nlohmann::json::array();
  for (const auto& path : report.output.written) written.push_back(path.string());
  nlohmann::json stage_times = nlohmann::json::array();
  for (const StageTime& t : report.stage_times) {
    stage_times.push_back({{"stage", t.stage}, {"seconds", t.seconds}});
  }
  const TrackBuildReport& t = report.tracks;
  return {{"num_frames", report.num_frames},
          {"extract", ToJson(report.extract)},
          {"match", ToJson(report.match)},
          {"fill_in_frames", report.fill_in_frames},
          {"localized_frames", report.localize.localized},
          {"tracks",
           {{"num_tracks", t.num_tracks},
            {"mean_track_length", t.mean_track_length},
            {"num_conflicting_tracks", t.num_conflicting_tracks},
            {"num_dropped_matches", t.num_dropped_matches}}},
          {"self_calibration", ToJson(report.self_calibration)},
          {"mapper", report.global_mapper ? "global" : "incremental"},
          {"global_model_set_aside", report.global_mapper_set_aside.has_value()},
          {"mapping", MapperReportJson(report.mapper)},
          {"models", models},
          {"written", written},
          {"stage_times", stage_times},
          {"total_seconds", report.total_seconds},
          {"peak_memory_bytes", report.peak_memory_bytes}};
}

}  // namespace loopsfm
