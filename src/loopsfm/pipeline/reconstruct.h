#pragma once
// The whole job in one call: extract, match, map, export. Every stage resumes from what
// OUT/database.db already holds, so an interrupted run continues where it stopped.
//
// Outputs: OUT/database.db (COLMAP-compatible), OUT/mapper_checkpoint.bin or
// OUT/global_mapper_checkpoint.bin (mapping state, pipeline/mapper_checkpoint.h and
// global_mapper_checkpoint.h), then what ReconstructOptions::output asks for
// (pipeline/export.h: COLMAP models, PLY, trajectory, frames, transforms.json, undistorted
// layout, report).

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "loopsfm/pipeline/export.h"
#include "loopsfm/pipeline/extract.h"
#include "loopsfm/pipeline/localize.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/pipeline/segment_mapping.h"
#include "loopsfm/sfm/global_mapper.h"
#include "loopsfm/sfm/incremental_mapper.h"
#include "loopsfm/sfm/self_calibration.h"
#include "loopsfm/util/progress.h"

namespace loopsfm {

enum class MapperKind { kIncremental, kGlobal };

struct ReconstructOptions {
  ExtractOptions extract;
  MatchOptions match;
  // Adaptive keyframes: rounds of in-between frames added where two consecutive kept frames
  // have no verified pair (a fast turn, a blurred stretch): the middle frame of the gap is
  // extracted and matched, and again in the halves that still break; 0: none. After
  // mapping, kept frames that no model registered get the middle frames on both sides, and
  // mapping runs once more (only then).
  int fill_in_rounds = 3;
  // After mapping, give every frame between keyframes a pose (pipeline/localize.h).
  bool all_frames = false;
  FrameLocalizerOptions localize;
  // Estimate the focal length of cameras without --intrinsics before mapping.
  bool self_calibrate = true;
  SelfCalibrationOptions self_calibration;
  // Which mapper builds the models: the incremental one (with loop closing) or the global
  // one (sfm/global_mapper.h), which uses `mapper`'s bundle, triangulation and filtering
  // settings and saves OUT/global_mapper_checkpoint.bin after each stage (with
  // checkpoint_interval_seconds > 0, whatever its value).
  MapperKind mapper_kind = MapperKind::kIncremental;
  IncrementalMapperOptions mapper;
  GlobalMapperOptions global_mapper;
  // Where the global mapper warns that its model is likely bent or broken
  // (GlobalMapperReport::Doubtful), set that model aside and map the video again with the
  // incremental mapper (with loop closing and checkpoints as it would have alone); false:
  // keep the global mapper's model, with its warning.
  bool remap_doubtful_global = true;
  // The incremental mapper on segments of the video (segment_mapping.h) where
  // segments.num_segments > 1; checkpoints (checkpoint_interval_seconds) then go to
  // OUT/segments/, one per segment.
  SegmentMappingOptions segments;
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
  // Who follows the progress and may ask the run to stop (null: nobody); must outlive the
  // run. The stages of a reconstruction get the reconstruction's.
  const RunHooks* hooks = nullptr;
  void Check() const;
};

struct StageTime {
  std::string stage;
  double seconds = 0.0;
};


// Every frame of the source along the video, for the report: which were kept and why, which
// were judged blurred, which were localised between keyframes (--all-frames).
struct FrameTimeline {
  // Frames of the source: all that adaptive selection read, else up to the last kept one.
  int frames_read = 0;
  // Source index and KeyframeReasonName of each kept frame, in source order ("" for frames
  // of databases older than the reasons).
  std::vector<std::pair<int, std::string>> kept;
  // Source indices judged blurred by adaptive selection (kept or not).
  std::vector<int> blurred;
  // Source indices of the frames localised between keyframes (any model).
  std::vector<int> localized;
};

struct ReconstructReport {
  size_t num_frames = 0;
  ExtractReport extract;
  MatchReport match;
  // In-between frames added by the fill-in rounds, and the gaps left unfilled.
  int fill_in_frames = 0;
  int fill_in_unfilled = 0;
  LocalizeReport localize;
  FrameTimeline timeline;
  TrackBuildReport tracks;
  SelfCalibrationReport self_calibration;
  MapperReport mapper;
  // With the global mapper: its stages. Where its model was set aside as doubtful and the
  // video mapped again (ReconstructOptions::remap_doubtful_global), the global mapper's own
  // mapping report is global_mapper_set_aside, and `mapper` is the incremental mapper's.
  std::optional<GlobalMapperReport> global_mapper;
  std::optional<MapperReport> global_mapper_set_aside;
  // With segments: each segment's mapping and the merge.
  std::optional<SegmentMappingReport> segments;
  // What the export wrote, with a summary of each model.
  ExportReport output;
  std::vector<StageTime> stage_times;
  double total_seconds = 0.0;
  long long peak_memory_bytes = 0;
};

ReconstructReport Reconstruct(const std::filesystem::path& input,
                              const std::filesystem::path& output_dir,
                              const ReconstructOptions& options);

// Reconstruct's mapping, localisation and export on a database that extract and match filled,
// into `output_dir` (which may hold the database or not). `input` is the video or folder the
// frames came from; empty: the source the database recorded, if it is still there. Without a
// source, the points are not coloured, and all_frames, fill-in frames after mapping and the
// formats that need the frames (images, gsplat) are refused. options.extract, .match and
// .overwrite are not used.
ReconstructReport MapDatabase(const std::filesystem::path& database_path,
                              const std::filesystem::path& input,
                              const std::filesystem::path& output_dir,
                              const ReconstructOptions& options);

// The report as JSON: counts, each model's summary and cameras, what was written, stage times
// (reconstruct_json.cc).
nlohmann::json ToJson(const ReconstructReport& report);

// The fill-in rounds of ReconstructOptions::fill_in_rounds on a matched database: extract
// and match the middle frame of each gap between consecutive kept frames that have no
// verified pair, until none is left or the rounds are spent.
void FillInGaps(const std::filesystem::path& input, Database& database,
                const ReconstructOptions& options, ReconstructReport* report);

// The alternate pose diagnostic as CSV: one line per registration, both rounds.
void WriteRegistrationRounds(const std::filesystem::path& path,
                             const std::vector<RegistrationRounds>& rounds);

// Loads frames, keypoints, verified geometries and tracks for the mappers.
MapperInput LoadMapperInput(const Database& database, TrackBuildReport* tracks_report);

}  // namespace loopsfm
