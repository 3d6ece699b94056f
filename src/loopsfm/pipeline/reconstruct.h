#pragma once
// The whole job in one call: extract, match, map, export. Every stage resumes from what
// OUT/database.db already holds, so an interrupted run continues where it stopped.
//
// Outputs: OUT/database.db (COLMAP-compatible), OUT/mapper_checkpoint.bin (mapping state,
// pipeline/mapper_checkpoint.h), then what ReconstructOptions::output asks for
// (pipeline/export.h: COLMAP models, PLY, trajectory, frames, transforms.json, undistorted
// layout, report).

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "loopsfm/pipeline/export.h"
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
  // What is written after mapping.
  ExportOptions output;
  // Start again: delete OUT/database.db (and its journal) before the run, instead of
  // resuming from it (a database made from another input or with other options is refused).
  bool overwrite = false;
  // Ground truth (trajectory file) to score the path against in the report; empty: none.
  std::filesystem::path groundtruth;
  // Save the mapper's state to OUT/mapper_checkpoint.bin every this many seconds of
  // mapping, and when it has finished, so a rerun goes on from there; 0: never.
  double checkpoint_interval_seconds = 60.0;
  // Show progress on stderr.
  bool show_progress = true;
  void Check() const;
};

struct StageTime {
  std::string stage;
  double seconds = 0.0;
};


struct ReconstructReport {
  size_t num_frames = 0;
  ExtractReport extract;
  MatchReport match;
  TrackBuildReport tracks;
  SelfCalibrationReport self_calibration;
  MapperReport mapper;
  // What the export wrote, with a summary of each model.
  ExportReport output;
  std::vector<StageTime> stage_times;
  double total_seconds = 0.0;
  long long peak_memory_bytes = 0;
};

ReconstructReport Reconstruct(const std::filesystem::path& input,
                              const std::filesystem::path& output_dir,
                              const ReconstructOptions& options);

// The alternate pose diagnostic as CSV: one line per registration, both rounds.
void WriteRegistrationRounds(const std::filesystem::path& path,
                             const std::vector<RegistrationRounds>& rounds);

// Loads frames, keypoints, verified geometries and tracks for the mappers.
MapperInput LoadMapperInput(const Database& database, TrackBuildReport* tracks_report);

}  // namespace loopsfm
