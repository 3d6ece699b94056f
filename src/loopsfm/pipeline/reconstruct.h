#pragma once
// The whole job in one call: extract, match, map, export. Every stage resumes from what
// OUT/database.db already holds, so an interrupted run continues where it stopped.
//
// Outputs:
//   OUT/database.db                       COLMAP-compatible database
//   OUT/sparse/<k>/{cameras,images,points3D}.bin (and .txt with text output), one folder per
//                                         model, largest first
//   OUT/points.ply                        coloured point cloud of model 0
//   OUT/trajectory.txt                    camera-to-world poses of model 0, by frame name

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "loopsfm/pipeline/extract.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/sfm/incremental_mapper.h"
#include "loopsfm/sfm/self_calibration.h"

namespace loopsfm {

struct ReconstructOptions {
  ExtractOptions extract;
  MatchOptions match;
  // Estimate the focal length of cameras without --intrinsics before mapping.
  bool self_calibrate = true;
  SelfCalibrationOptions self_calibration;
  IncrementalMapperOptions mapper;
  // Also write the COLMAP model as text files.
  bool write_text = false;
  // Show progress on stderr.
  bool show_progress = true;
  void Check() const;
};

struct StageTime {
  std::string stage;
  double seconds = 0.0;
};

struct ModelSummary {
  std::filesystem::path path;
  size_t num_registered = 0;
  size_t num_points = 0;
  double mean_track_length = 0.0;
  double mean_reprojection_error = 0.0;
  // The model's cameras, as refined.
  std::vector<Camera> cameras;
};

struct ReconstructReport {
  size_t num_frames = 0;
  ExtractReport extract;
  MatchReport match;
  TrackBuildReport tracks;
  SelfCalibrationReport self_calibration;
  MapperReport mapper;
  std::vector<ModelSummary> models;
  std::vector<StageTime> stage_times;
  double total_seconds = 0.0;
  long long peak_memory_bytes = 0;
};

ReconstructReport Reconstruct(const std::filesystem::path& input,
                              const std::filesystem::path& output_dir,
                              const ReconstructOptions& options);

// Loads frames, keypoints, verified geometries and tracks for the mappers.
MapperInput LoadMapperInput(const Database& database, TrackBuildReport* tracks_report);

// Writes OUT/sparse/<k>, OUT/points.ply and OUT/trajectory.txt for the given models.
std::vector<ModelSummary> ExportModels(const std::vector<Reconstruction>& models,
                                       const std::filesystem::path& output_dir, bool write_text);

// Sets point colours by reading the source frames again (streamed) and averaging the
// pixel colours of each point's observations.
void ColorizeFromSource(const std::filesystem::path& input, std::vector<Reconstruction>* models);

}  // namespace loopsfm
