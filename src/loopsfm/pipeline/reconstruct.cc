#include "loopsfm/pipeline/reconstruct.h"

#include <algorithm>
#include <fstream>
#include <set>
#include <unordered_map>

#include "loopsfm/eval/trajectory_metrics.h"
#include "loopsfm/loop/loop_closing.h"
#include "loopsfm/pipeline/global_mapper_checkpoint.h"
#include "loopsfm/pipeline/mapper_checkpoint.h"
#include "loopsfm/pipeline/run_report.h"
#include "loopsfm/report/html_report.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/storage/ply.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/progress.h"
#include "loopsfm/util/timer.h"
#include "loopsfm/video/frame_source.h"

namespace loopsfm {
namespace fs = std::filesystem;

void ReconstructOptions::Check() const {
  extract.Check();
  match.Check();
  self_calibration.Check();
  mapper.Check();
  global_mapper.Check();
  segments.Check();
  LOOPSFM_REQUIRE_OPTION(segments.num_segments == 1 || !mapper.loop_closure.withhold_loop_pairs,
                         "segments withhold the loop pairs until they are merged already; leave "
                         "out withhold_loop_pairs");
  output.Check();
}

MapperInput LoadMapperInput(const Database& database, TrackBuildReport* tracks_report) {
  MapperInput input;
  input.cameras = database.ReadCameras();
  for (const Frame& frame : FramesInCaptureOrder(database)) {
    MapperFrame mf;
    mf.image_id = frame.image_id;
    mf.camera_id = frame.camera_id;
    mf.name = frame.name;
    for (const FeatureKeypoint& kp : database.ReadKeypoints(frame.image_id)) {
      mf.points2D.emplace_back(kp.x, kp.y);
    }
    input.frames.push_back(std::move(mf));
  }
  std::unordered_map<image_t, size_t> num_points2D;
  for (const MapperFrame& frame : input.frames) num_points2D[frame.image_id] = frame.points2D.size();
  for (auto& [pair, geometry] : database.ReadAllTwoViewGeometries()) {
    if (geometry.IsVerified()) input.pairs.push_back({pair, std::move(geometry)});
  }
  std::vector<VerifiedPairMatches> verified;
  for (const MapperPair& pair : input.pairs) {
    verified.push_back({pair.pair, &pair.geometry.inlier_matches});
  }
  input.tracks = BuildTracks(num_points2D, verified, {}, tracks_report);
  return input;
}

void WriteRegistrationRounds(const fs::path& path, const std::vector<RegistrationRounds>& rounds) {
  std::ofstream out(path);
  out << "frame,correspondences,inliers,inlier_ratio,second_correspondences,second_inliers,"
         "second_inlier_ratio,second_pose_found,second_centre_distance,second_rotation_deg\n";
  for (const RegistrationRounds& r : rounds) {
    const double ratio = static_cast<double>(r.num_inliers) / std::max(1, r.num_correspondences);
    const double second_ratio =
        static_cast<double>(r.second_num_inliers) / std::max(1, r.second_num_correspondences);
    out << fmt::format("{},{},{},{:.4f},{},{},{:.4f},{},{:.6g},{:.4f}\n", r.frame,
                       r.num_correspondences, r.num_inliers, ratio, r.second_num_correspondences,
                       r.second_num_inliers, second_ratio, r.second_pose_found ? 1 : 0,
                       r.second_centre_distance, r.second_rotation_deg);
  }
  if (!out) {
    throw StorageError(fmt::format("cannot write '{}': check that the folder is writable",
                                   path.string()));
  }
}

namespace {

// The source index of the frame midway between kept frames a and b, when one lies between.
std::optional<int> GapMiddle(const std::unordered_map<image_t, FrameOrigin>& origins, image_t a,
                             image_t b) {
  const auto from = origins.find(a), to = origins.find(b);
  if (from == origins.end() || to == origins.end()) return std::nullopt;
  const int64_t first = from->second.source_index, last = to->second.source_index;
  if (last - first < 2) return std::nullopt;
  return static_cast<int>((first + last) / 2);
}

// Consecutive kept frames (capture order) without a verified pair between them: the source
// index of each gap's middle frame; gaps with no frame between them are counted in
// `unfillable`.
std::vector<int> UnverifiedGapMiddles(const Database& database, int* unfillable) {
  std::set<std::pair<image_t, image_t>> verified;
  for (const VerifiedPair& pair : database.ReadVerifiedPairs()) {
    verified.insert(std::minmax(pair.pair.image_id1, pair.pair.image_id2));
  }
  const auto origins = database.ReadFrameOrigins();
  const std::vector<Frame> frames = FramesInCaptureOrder(database);
  std::vector<int> middles;
  *unfillable = 0;
  for (size_t i = 1; i < frames.size(); ++i) {
    const image_t a = frames[i - 1].image_id, b = frames[i].image_id;
    if (verified.count(std::minmax(a, b))) continue;
    if (const std::optional<int> middle = GapMiddle(origins, a, b)) {
      middles.push_back(*middle);
    } else {
      ++*unfillable;
    }
  }
  return middles;
}

// Kept frames that no model registered: the middles of the gaps on both sides of each (in
// source order, once each); `unregistered` counts them.
std::vector<int> MiddlesAroundUnregistered(const Database& database,
                                           const std::vector<Reconstruction>& models,
                                           int* unregistered) {
  auto registered = [&](image_t id) {
    return std::any_of(models.begin(), models.end(), [&](const Reconstruction& model) {
      return model.ExistsImage(id) && model.IsRegistered(id);
    });
  };
  const auto origins = database.ReadFrameOrigins();
  const std::vector<Frame> frames = FramesInCaptureOrder(database);
  std::set<int> middles;
  *unregistered = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    if (registered(frames[i].image_id)) continue;
    ++*unregistered;
    for (size_t j : {i - 1, i + 1}) {  // the neighbours before and after (i - 1 wraps at 0)
      if (j >= frames.size()) continue;
      const auto [a, b] = std::minmax(i, j);
      if (auto middle = GapMiddle(origins, frames[a].image_id, frames[b].image_id)) {
        middles.insert(*middle);
      }
    }
  }
  return {middles.begin(), middles.end()};
}

FrameTimeline ReadFrameTimeline(const Database& database, int frames_read) {
  FrameTimeline timeline;
  timeline.frames_read = frames_read;
  for (const auto& [id, origin] : database.ReadFrameOrigins()) {
    timeline.kept.emplace_back(static_cast<int>(origin.source_index), origin.reason);
  }
  std::sort(timeline.kept.begin(), timeline.kept.end());
  if (!timeline.kept.empty()) {
    timeline.frames_read = std::max(timeline.frames_read, timeline.kept.back().first + 1);
  }
  if (const std::optional<std::string> meta = database.ReadMeta("keyframes")) {
    const nlohmann::json summary = nlohmann::json::parse(*meta, nullptr, false);
    if (summary.is_object() && summary.contains("blurred") && summary["blurred"].is_array()) {
      for (const auto& index : summary["blurred"]) {
        if (index.is_number_integer()) timeline.blurred.push_back(index.get<int>());
      }
    }
  }
  return timeline;
}

}  // namespace

void FillInGaps(const fs::path& input, Database& database, const ReconstructOptions& options,
                ReconstructReport* report) {
  std::vector<int> middles = UnverifiedGapMiddles(database, &report->fill_in_unfilled);
  for (int round = 0; round < options.fill_in_rounds && !middles.empty(); ++round) {
    const ExtractReport extracted =
        ExtractFillInFrames(input, database, options.extract, middles);
    report->fill_in_frames += extracted.frames_extracted;
    const MatchReport matched = MatchPairs(database, options.match);
    spdlog::info("fill-in round {}: {} in-between frame{} where kept frames did not verify, "
                 "{} pairs matched",
                 round + 1, middles.size(), middles.size() == 1 ? "" : "s",
                 matched.num_pairs_matched);
    middles = UnverifiedGapMiddles(database, &report->fill_in_unfilled);
  }
  // What is still broken after the last round.
  report->fill_in_unfilled += static_cast<int>(middles.size());
  if (report->fill_in_frames > 0 || report->fill_in_unfilled > 0) {
    spdlog::info("fill-in: {} in-between frames added; {} gaps between kept frames still "
                 "without a verified pair",
                 report->fill_in_frames, report->fill_in_unfilled);
  }
}

namespace {

// The mapper (incremental or global) on segments; with checkpoints (the incremental mapper),
// each segment's in OUT/segments/segment_K.bin.
std::vector<Reconstruction> MapSegmented(const MapperInput& mapper_input,
                                         const ReconstructOptions& options,
                                         const fs::path& checkpoint_dir, int pass,
                                         ReconstructReport* report) {
  report->segments.emplace();
  SegmentMappingOptions segments = options.segments;
  if (options.mapper_kind == MapperKind::kGlobal) {
    segments.global_mapper = options.global_mapper;
    segments.global_mapper->verification = options.match.verification;
    segments.remap_doubtful_global = options.remap_doubtful_global;
    segments.global_mapper->stop_when_bent = options.remap_doubtful_global;
  } else if (options.checkpoint_interval_seconds > 0.0) {
    segments.checkpoint_dir = checkpoint_dir;
    segments.checkpoint_interval_seconds = options.checkpoint_interval_seconds;
  }
  std::vector<Reconstruction> models = MapInSegments(mapper_input, options.mapper, segments,
                                                     &*report->segments, &report->mapper);
  const SegmentMappingReport& s = *report->segments;
  const std::string suffix = pass == 0 ? "" : " (again)";
  report->stage_times.push_back({"map: segments" + suffix, s.seconds_segments});
  report->stage_times.push_back({"map: merge" + suffix, s.seconds_merging});
  report->stage_times.push_back({"map: loops" + suffix, s.seconds_loops});
  return models;
}

// The incremental mapper with loop closing; with checkpoints, in OUT/mapper_checkpoint.bin
// (the fingerprint digests the whole mapper input: only with checkpoints).
std::vector<Reconstruction> MapIncrementally(const MapperInput& mapper_input,
                                             const ReconstructOptions& options,
                                             const fs::path& checkpoint_path,
                                             const std::string& stage, ReconstructReport* report) {
  Timer timer;
  std::optional<MapperCheckpointFile> checkpoint;
  if (options.checkpoint_interval_seconds > 0.0) {
    checkpoint.emplace(checkpoint_path, mapper_input, options.mapper,
                       options.checkpoint_interval_seconds);
  }
  Progress progress("map", mapper_input.frames.size(), options.show_progress, options.hooks);
  std::vector<Reconstruction> models =
      MapWithLoopClosing(mapper_input, options.mapper, &report->mapper,
                         [&](size_t registered, size_t) { progress.Set(registered); },
                         checkpoint ? checkpoint->checkpointing() : MapperCheckpointing{});
  report->stage_times.push_back({stage, timer.ElapsedSeconds()});
  return models;
}

// The global mapper; with checkpoints, after each stage in OUT/global_mapper_checkpoint.bin.
// Where it doubts its model (likely bent or broken) and options.remap_doubtful_global, the
// incremental mapper maps the video again (its checkpoint: incremental_checkpoint_path).
std::vector<Reconstruction> MapGlobally(const MapperInput& mapper_input,
                                        const ReconstructOptions& options,
                                        const fs::path& checkpoint_path,
                                        const fs::path& incremental_checkpoint_path, int pass,
                                        ReconstructReport* report) {
  report->global_mapper.emplace();
  report->global_mapper_set_aside.reset();
  GlobalMapperOptions global_options = options.global_mapper;
  global_options.verification = options.match.verification;
  // A bent component is found before its bundles: when its model would be set aside, the
  // bundles are not run.
  global_options.stop_when_bent = options.remap_doubtful_global;
  std::optional<GlobalMapperCheckpointFile> checkpoint;
  if (options.checkpoint_interval_seconds > 0.0) {
    checkpoint.emplace(checkpoint_path, mapper_input, options.mapper, global_options);
  }
  std::vector<Reconstruction> models = RunGlobalMapper(
      mapper_input, options.mapper, global_options, &*report->global_mapper, &report->mapper,
      options.hooks, checkpoint ? checkpoint->checkpointing() : GlobalMapperCheckpointing{});
  const GlobalMapperReport& g = *report->global_mapper;
  const std::string suffix = pass == 0 ? "" : " (again)";
  report->stage_times.push_back({"map: view graph" + suffix, g.seconds_view_graph});
  report->stage_times.push_back({"map: rotations" + suffix, g.seconds_rotations});
  report->stage_times.push_back({"map: positions" + suffix, g.seconds_positioning});
  report->stage_times.push_back(
      {"map: structure" + suffix, g.seconds_triangulation + g.seconds_bundles});
  if (g.num_pairs_across_cuts > 0) {
    report->stage_times.push_back({"map: joining" + suffix, g.seconds_joining});
  }
  if (!g.Doubtful()) return models;
  if (!options.remap_doubtful_global) {
    spdlog::warn("global mapper: its model kept although likely {}, as --keep-global-model "
                 "asks; --mapper incremental maps such a video without that fault",
                 g.Fault());
    return models;
  }
  spdlog::warn("global mapper: likely {} (see the warning above); mapping the video with the "
               "incremental mapper instead (--keep-global-model keeps the global mapper's "
               "model)",
               g.Fault());
  ThrowIfStopRequested(options.hooks, "global mapping");
  report->global_mapper_set_aside = std::move(report->mapper);
  report->mapper = {};
  return MapIncrementally(mapper_input, options, incremental_checkpoint_path,
                          "map: incremental" + suffix, report);
}

}  // namespace

namespace {

// What follows matching: mapping (and the fill-in pass around unregistered frames, when the
// frames' source is known), localisation, export and the report; Reconstruct's work and
// MapDatabase's. `input` may be empty (the source is unknown).
void MapAndExport(Database& database, const fs::path& database_path, const fs::path& input,
                  const fs::path& output_dir, const ReconstructOptions& options,
                  const std::optional<std::vector<TrajectoryEntry>>& groundtruth,
                  const Timer& total, ReconstructReport* report) {
  const fs::path checkpoint_path = output_dir / "mapper_checkpoint.bin";
  const fs::path global_checkpoint_path = output_dir / "global_mapper_checkpoint.bin";
  const fs::path segment_checkpoints = output_dir / "segments";
  Timer stage;
  // Mapping, and once more when adaptive keyframes left kept frames unregistered (a turn
  // too fast for the frames kept): in-between frames around them are added first.
  MapperInput mapper_input;
  std::vector<Reconstruction> models;
  const bool adaptive = !input.empty() && options.fill_in_rounds > 0 &&
                        database.ReadMeta("keyframes").has_value();
  for (int pass = 0;; ++pass) {
    ThrowIfStopRequested(options.hooks, pass == 0 ? "match" : "fill-in");
    stage.Restart();
    mapper_input = LoadMapperInput(database, &report->tracks);
    report->stage_times.push_back({pass == 0 ? "tracks" : "tracks-again", stage.ElapsedSeconds()});
    spdlog::info("tracks: {} (mean length {:.2f}; {} conflicting split, {} matches left out)",
                 report->tracks.num_tracks, report->tracks.mean_track_length,
                 report->tracks.num_conflicting_tracks, report->tracks.num_dropped_matches);

    if (options.self_calibrate) {
      stage.Restart();
      SelfCalibrationOptions self_calibration = options.self_calibration;
      self_calibration.verification = options.match.verification;
      report->self_calibration = SelfCalibrate(self_calibration, &mapper_input);
      report->stage_times.push_back(
          {pass == 0 ? "self-calibration" : "self-calibration-again", stage.ElapsedSeconds()});
    }

    ThrowIfStopRequested(options.hooks, "self-calibration");
    stage.Restart();
    if (options.segments.num_segments > 1) {
      models = MapSegmented(mapper_input, options, segment_checkpoints, pass, report);
    } else if (options.mapper_kind == MapperKind::kGlobal) {
      models = MapGlobally(mapper_input, options, global_checkpoint_path, checkpoint_path, pass,
                           report);
    } else {
      models = MapIncrementally(mapper_input, options, checkpoint_path,
                                pass == 0 ? "map" : "map-again", report);
    }
    // Once per database: a rerun (which maps the fill-ins from the start) adds no more.
    if (pass > 0 || !adaptive || database.ReadMeta("fill_in_after_mapping")) break;
    stage.Restart();
    int unregistered = 0;
    const std::vector<int> middles = MiddlesAroundUnregistered(database, models, &unregistered);
    if (middles.empty()) break;
    spdlog::info("fill-in: {} kept frame{} not registered; {} in-between frames around them, "
                 "then mapping again",
                 unregistered, unregistered == 1 ? " was" : "s were", middles.size());
    report->fill_in_frames +=
        ExtractFillInFrames(input, database, options.extract, middles).frames_extracted;
    MatchPairs(database, options.match);
    database.WriteMeta("fill_in_after_mapping", std::to_string(middles.size()));
    report->stage_times.push_back({"fill-in-again", stage.ElapsedSeconds()});
  }
  if (models.empty()) {
    spdlog::warn("no model could be started: no frame pair had enough matches with a wide enough "
                 "baseline ({} frames, {} verified pairs). 3D needs the camera to move through "
                 "the scene: a camera that stands still or only turns on the spot gives no "
                 "baseline. Otherwise try --pairs exhaustive, more frames (--every 1), or "
                 "--intrinsics",
                 mapper_input.frames.size(), mapper_input.pairs.size());
  }

  // A pose for every frame; none from an earlier run is left behind when this one has none.
  const fs::path localized_path = output_dir / "localized.txt";
  std::vector<LocalizedFrame> localized;
  fs::remove(localized_path);
  if (options.all_frames && !models.empty()) {
    stage.Restart();
    localized = LocalizeSkippedFrames(input, database, models, options.localize,
                                      options.show_progress, options.hooks, &report->localize);
    report->stage_times.push_back({"localise", stage.ElapsedSeconds()});
    const LocalizeReport& l = report->localize;
    spdlog::info("localise: {} of the {} frames between keyframes got a pose ({} did not), "
                 "{:.1f} ms a frame",
                 l.localized, l.localized + l.not_localized, l.not_localized,
                 1000.0 * l.seconds / std::max(1, l.frames_read));
  }

  stage.Restart();
  std::vector<std::string> frame_names;
  for (const MapperFrame& frame : mapper_input.frames) frame_names.push_back(frame.name);
  report->output = Export(&models, frame_names, input, output_dir, options.output, localized);
  if (options.all_frames && !models.empty()) {
    WriteTrajectoryFile(localized_path, LocalizedTrajectory(localized));
    report->output.written.push_back(localized_path);
  }
  report->stage_times.push_back({"export", stage.ElapsedSeconds()});
  report->total_seconds = total.ElapsedSeconds();
  report->peak_memory_bytes = PeakResidentBytes();
  // The frames loop closing tied together, for plots (`loopsfm eval --plot-links`); none
  // from an earlier run is left behind when this one does not close loops.
  const fs::path links_path = output_dir / "loop_links.txt";
  if (options.mapper_kind == MapperKind::kIncremental &&
      options.mapper.loop_closure.method != LoopClosingMethod::kNone) {
    WriteLoopLinksFile(links_path, report->mapper.loop_links);
    report->output.written.push_back(links_path);
  } else {
    fs::remove(links_path);
  }
  if (options.mapper.record_alternate_poses) {
    WriteRegistrationRounds(output_dir / "registrations.csv", report->mapper.registrations);
    report->output.written.push_back(output_dir / "registrations.csv");
  } else {
    fs::remove(output_dir / "registrations.csv");
  }
  report->timeline = ReadFrameTimeline(database, report->extract.frames_read);
  for (const LocalizedFrame& frame : localized) {
    report->timeline.localized.push_back(frame.source_index);
  }
  if (options.output.formats.count(ExportFormat::kReport)) {
    stage.Restart();
    WriteHtmlReport(output_dir / "report.html",
                    RunReportData(*report, models, FramesInCaptureOrder(database),
                                  input.empty() ? database_path : input, output_dir,
                                  groundtruth));
    report->output.written.push_back(output_dir / "report.html");
    report->stage_times.push_back({"report", stage.ElapsedSeconds()});
    report->total_seconds = total.ElapsedSeconds();
  }
}

}  // namespace

ReconstructReport Reconstruct(const fs::path& input, const fs::path& output_dir,
                              const ReconstructOptions& given_options) {
  given_options.Check();
  // The stages report to the reconstruction's hooks.
  ReconstructOptions options = given_options;
  if (options.hooks) options.extract.hooks = options.match.hooks = options.hooks;
  Timer total;
  ReconstructReport report;
  // Refuse a bad input before anything is created.
  OpenFrameSource(input);
  std::optional<std::vector<TrajectoryEntry>> groundtruth;
  if (!options.groundtruth.empty()) groundtruth = ReadTrajectoryFile(options.groundtruth);
  CreateFolder(output_dir, "output folder ");
  const fs::path database_path = output_dir / "database.db";
  const fs::path checkpoint_path = output_dir / "mapper_checkpoint.bin";
  const fs::path segment_checkpoints = output_dir / "segments";
  if (options.overwrite) {
    for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(database_path.string() + suffix);
    fs::remove(checkpoint_path);
    fs::remove(output_dir / "global_mapper_checkpoint.bin");
    fs::remove_all(segment_checkpoints);
  }
  Database database = Database::Open(database_path.string());

  Timer stage;
  report.extract = ExtractFeatures(input, database, options.extract);
  report.stage_times.push_back({"extract", stage.ElapsedSeconds()});
  report.num_frames = database.NumFrames();
  spdlog::info("extract: {} frames ({} new), {:.0f} features/frame", report.num_frames,
               report.extract.frames_extracted, report.extract.FeaturesPerFrame());
  LogRankShares("extract: frames", report.extract.frames_per_rank);
  if (report.num_frames < 2) {
    throw InputError(fmt::format(
        "'{}' gave {} frame{}: a reconstruction needs at least two, taken while the camera "
        "moves; use a longer video (or --every 1 if frames were skipped)",
        input.string(), report.num_frames, report.num_frames == 1 ? "" : "s"));
  }

  ThrowIfStopRequested(options.hooks, "extract");
  stage.Restart();
  report.match = MatchPairs(database, options.match);
  report.stage_times.push_back({"match", stage.ElapsedSeconds()});
  spdlog::info("match ({}, {} kernel): {} pairs ({} matched now, {} stored before), {} verified "
               "now, {:.0f} mean inliers",
               PairStrategyName(options.match.strategy), report.match.kernel,
               report.match.num_pairs, report.match.num_pairs_matched,
               report.match.num_pairs_resumed, report.match.num_pairs_verified,
               report.match.MeanInliers());
  LogRankShares("match: pairs", report.match.pairs_per_rank);

  if (options.fill_in_rounds > 0 && database.ReadMeta("keyframes")) {
    stage.Restart();
    FillInGaps(input, database, options, &report);
    report.stage_times.push_back({"fill-in", stage.ElapsedSeconds()});
  }
  MapAndExport(database, database_path, input, output_dir, options, groundtruth, total, &report);
  return report;
}

ReconstructReport MapDatabase(const fs::path& database_path, const fs::path& input,
                              const fs::path& output_dir, const ReconstructOptions& given_options) {
  given_options.Check();
  ReconstructOptions options = given_options;
  Timer total;
  ReconstructReport report;
  // Refuse what cannot be done before anything is created.
  if (!fs::is_regular_file(database_path)) {
    throw InputError(fmt::format("database '{}' does not exist; make it with `loopsfm extract "
                                 "INPUT -d {}` and `loopsfm match -d {}`",
                                 database_path.string(), database_path.string(),
                                 database_path.string()));
  }
  if (!input.empty()) OpenFrameSource(input);
  std::optional<std::vector<TrajectoryEntry>> groundtruth;
  if (!options.groundtruth.empty()) groundtruth = ReadTrajectoryFile(options.groundtruth);
  Database database = Database::Open(database_path.string());
  if (!database.ReadMeta("match_fingerprint")) {
    throw InputError(fmt::format(
        "database '{}' holds no pairs that `loopsfm match` verified (the mapper starts from the "
        "two-view geometry that loopsfm's verification stores; from a database that COLMAP "
        "matched it starts no model): run `loopsfm match -d {}` first, or for a COLMAP "
        "database, `loopsfm extract` and `loopsfm match` on its images",
        database_path.string(), database_path.string()));
  }
  fs::path source = input;
  if (source.empty()) {
    const std::optional<std::string> recorded = database.ReadMeta("source_path");
    if (recorded && fs::exists(*recorded)) source = *recorded;
  }
  if (source.empty()) {
    for (ExportFormat format : {ExportFormat::kImages, ExportFormat::kGsplat}) {
      if (options.output.formats.count(format)) {
        throw InvalidArgument(fmt::format(
            "--export {} writes the frames, and the database records no source that is still "
            "there: pass the video or folder with --input, or leave {} out (e.g. --export "
            "colmap,ply,tum,nerfstudio,report)",
            ExportFormatName(format), ExportFormatName(format)));
      }
    }
    if (options.all_frames) {
      throw InvalidArgument("all frames need the video: pass it with --input");
    }
    options.output.colorize = false;
    spdlog::warn("the frames' source is unknown (pass it with --input): the points are not "
                 "coloured");
  }
  report.num_frames = database.NumFrames();
  if (report.num_frames < 2) {
    throw InputError(fmt::format("database '{}' holds {} frame{}: fill it with `loopsfm extract` "
                                 "and `loopsfm match` first",
                                 database_path.string(), report.num_frames,
                                 report.num_frames == 1 ? "" : "s"));
  }
  CreateFolder(output_dir, "output folder ");
  // Mapping only: no frames are added to the database.
  options.fill_in_rounds = 0;
  MapAndExport(database, database_path, source, output_dir, options, groundtruth, total, &report);
  return report;
}

}  // namespace loopsfm
