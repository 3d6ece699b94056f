#include "loopsfm/pipeline/segment_mapping.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <memory>
#include <optional>
#include <thread>
#include <unordered_map>
#include <vector>

#include "loopsfm/loop/loop_closing.h"
#include "loopsfm/pipeline/mapper_checkpoint.h"
#include "loopsfm/pipeline/wire_format.h"
#include "loopsfm/sfm/global_mapper.h"
#include "loopsfm/sfm/incremental_mapper.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/model_merger.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace fs = std::filesystem;

void SegmentMappingOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(num_segments >= 1, "segments must be at least 1, got {}", num_segments);
  LOOPSFM_REQUIRE_OPTION(overlap >= 2, "segment overlap must be at least 2 frames, got {}",
                         overlap);
  LOOPSFM_REQUIRE_OPTION(num_parallel >= 0, "segments mapped at once must not be negative, got {}",
                         num_parallel);
  LOOPSFM_REQUIRE_OPTION(checkpoint_interval_seconds >= 0.0,
                         "segment checkpoint interval must not be negative, got {}",
                         checkpoint_interval_seconds);
}

std::vector<std::pair<size_t, size_t>> PlanSegments(size_t num_frames, int num_segments,
                                                    int overlap) {
  if (num_frames == 0) return {};
  const size_t o = static_cast<size_t>(std::max(overlap, 0));
  size_t count = static_cast<size_t>(std::max(num_segments, 1));
  size_t length = num_frames;
  for (; count > 1; --count) {
    length = (num_frames + (count - 1) * o + count - 1) / count;  // rounded up
    if (length >= 2 * o) break;
  }
  if (count < static_cast<size_t>(num_segments)) {
    spdlog::warn("segments: {} frames make {} segment{} of at least {} frames (twice the overlap), "
                 "not {}",
                 num_frames, count, count == 1 ? "" : "s", 2 * o, num_segments);
  }
  if (count == 1) return {{0, num_frames}};
  std::vector<std::pair<size_t, size_t>> segments;
  for (size_t k = 0; k < count; ++k) {
    const size_t begin = k * (length - o);
    segments.push_back({begin, k + 1 == count ? num_frames : std::min(num_frames, begin + length)});
  }
  return segments;
}

std::vector<std::pair<size_t, size_t>> PlanSegmentsByCost(const std::vector<double>& frame_costs,
                                                          int num_segments, int overlap) {
  const size_t n = frame_costs.size();
  const std::vector<std::pair<size_t, size_t>> equal = PlanSegments(n, num_segments, overlap);
  std::vector<double> before(n + 1, 0.0);  // before[k]: the cost of frames [0, k)
  for (size_t k = 0; k < n; ++k) before[k + 1] = before[k] + std::max(frame_costs[k], 0.0);
  if (equal.size() < 2 || before[n] <= 0.0) return equal;
  const size_t o = static_cast<size_t>(std::max(overlap, 0));
  // Greedy: each segment as short as reaches `most` (and 2 * overlap frames), the next
  // starting `overlap` frames before its end.
  auto plan_under = [&](double most) {
    std::vector<std::pair<size_t, size_t>> plan;
    size_t begin = 0;
    while (true) {
      if (before[n] - before[begin] <= most) {
        plan.push_back({begin, n});
        break;
      }
      size_t end = std::lower_bound(before.begin() + begin + 1, before.end(),
                                    before[begin] + most) - before.begin();
      end = std::min(n, std::max(end, begin + 2 * o));
      plan.push_back({begin, end});
      if (end == n) break;
      begin = end - o;
    }
    return plan;
  };
  // The plans for bounds from the mean cost of a segment up to all of it: the one of few
  // enough segments, the last of 2 * overlap frames too, that costs least at its most costly
  // segment. (Whether a bound admits a plan is not monotonic in it, which rules out a
  // bisection; plans are cheap to make.)
  auto most_of = [&](const std::vector<std::pair<size_t, size_t>>& plan) {
    double most = 0.0;
    for (const auto& [begin, end] : plan) most = std::max(most, before[end] - before[begin]);
    return most;
  };
  std::vector<std::pair<size_t, size_t>> best = equal;
  double best_most = most_of(equal);
  constexpr int kSteps = 4096;
  const double low = before[n] / static_cast<double>(equal.size());
  for (int step = 0; step <= kSteps; ++step) {
    const std::vector<std::pair<size_t, size_t>> plan =
        plan_under(low + (before[n] - low) * step / kSteps);
    if (plan.size() > equal.size() || plan.back().second - plan.back().first < 2 * o) continue;
    if (const double most = most_of(plan); most < best_most) {
      best = plan;
      best_most = most;
    }
  }
  return best;
}

namespace {

struct SegmentResult {
  std::optional<Reconstruction> model;  // the largest
  MapperReport mapper_report;
  SegmentReport report;
};

// Maps a part of the input (a segment's frames), by the global mapper where `global` is set
// (and again by the incremental mapper where remap_doubtful and the global mapper doubts its
// model); with a checkpoint path (the incremental mapper only), saves the mapping state
// there now and then, and goes on from what is there.
SegmentResult MapPart(const MapperInput& part, const IncrementalMapperOptions& options,
                      const std::optional<GlobalMapperOptions>& global, bool remap_doubtful,
                      const fs::path& checkpoint_path, double checkpoint_interval_seconds) {
  Timer timer;
  SegmentResult result;
  std::vector<Reconstruction> models;
  if (global) {
    GlobalMapperReport global_report;
    models = RunGlobalMapper(part, options, *global, &global_report, &result.mapper_report);
    result.report.global_set_aside = remap_doubtful && global_report.Doubtful();
    if (result.report.global_set_aside) {
      spdlog::warn("segment of {} frames: its global model set aside (likely {}); mapping it "
                   "again with the incremental mapper",
                   part.frames.size(), global_report.Fault());
      result.mapper_report = {};
      models = MapWithLoopClosing(part, options, &result.mapper_report);
    }
  } else {
    std::optional<MapperCheckpointFile> checkpoint;
    if (!checkpoint_path.empty()) {
      checkpoint.emplace(checkpoint_path, part, options, checkpoint_interval_seconds);
      result.report.resumed = checkpoint->Finished();
    }
    models = MapWithLoopClosing(part, options, &result.mapper_report, {},
                                checkpoint ? checkpoint->checkpointing() : MapperCheckpointing{});
  }
  result.report.num_models = static_cast<int>(models.size());
  result.report.num_loops_closed = static_cast<int>(result.mapper_report.loops_closed.size());
  if (!models.empty()) {
    result.report.num_registered = static_cast<int>(models[0].NumRegImages());
    result.model = std::move(models[0]);
  }
  result.report.seconds = timer.ElapsedSeconds();
  return result;
}

// What a rank that maps a segment sends back: its report, the mapper's, its largest model.
void PutSegmentResult(ByteWriter& w, const SegmentResult& result) {
  w.Put(result.report);
  w.PutString(MapperReportJson(result.mapper_report).dump());
  w.Put<uint8_t>(result.model ? 1 : 0);
  if (result.model) PutMappedState(w, result.model->SaveMapped());
}

SegmentResult GetSegmentResult(ByteReader& r, const MapperInput& part) {
  SegmentResult result;
  result.report = r.Get<SegmentReport>();
  result.mapper_report = MapperReportFromJson(nlohmann::json::parse(r.GetString()));
  if (r.Get<uint8_t>()) {
    result.model = EmptyReconstruction(part);
    result.model->RestoreMapped(GetMappedState(r));
  }
  return result;
}

// A frame's cost in mapping: its keypoints in tracks, by capture index.
std::vector<double> TrackedKeypointsPerFrame(const MapperInput& input) {
  std::unordered_map<image_t, size_t> index;
  for (size_t k = 0; k < input.frames.size(); ++k) index[input.frames[k].image_id] = k;
  std::vector<double> costs(input.frames.size(), 0.0);
  for (const Track& track : input.tracks) {
    for (const TrackElement& el : track.elements) costs[index.at(el.image_id)] += 1.0;
  }
  return costs;
}

// Stage 1: every segment mapped, as many at once as the ranks' threads allow (each segment
// with its share of the mapper's threads), here and on the other ranks of an MPI run.
std::vector<SegmentResult> MapSegments(const MapperInput& input,
                                       const IncrementalMapperOptions& mapper_options,
                                       const SegmentMappingOptions& options,
                                       const std::vector<std::pair<size_t, size_t>>& plan) {
  const int threads = mapper_options.num_threads > 0
                          ? mapper_options.num_threads
                          : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int parallel = std::min(static_cast<int>(plan.size()),
                                options.num_parallel > 0 ? options.num_parallel : threads);
  IncrementalMapperOptions segment_options = mapper_options;
  segment_options.num_threads = std::max(1, threads / std::max(parallel, 1));
  fs::path checkpoint_dir;
  if (!options.checkpoint_dir.empty() && !options.global_mapper) {
    // Absolute, for the ranks that write their segments' checkpoints there too.
    checkpoint_dir = fs::absolute(options.checkpoint_dir);
    std::error_code ec;
    fs::create_directories(checkpoint_dir, ec);
    if (ec) {
      throw StorageError(fmt::format("cannot create the segment checkpoint folder '{}': {}",
                                     checkpoint_dir.string(), ec.message()));
    }
  }
  auto checkpoint_of = [&](size_t k) {
    return checkpoint_dir.empty() ? fs::path()
                                  : checkpoint_dir / fmt::format("segment_{}.bin", k);
  };
  // Each segment's part of the input, made once (for the request and the model that comes
  // back, or for mapping here) and let go when the segment is done. Slots are distinct per
  // segment, so the threads mapping segments here do not share one.
  std::vector<std::optional<MapperInput>> parts(plan.size());
  auto part_of = [&](size_t k) -> const MapperInput& {
    if (!parts[k]) parts[k] = InputPart(input, plan[k].first, plan[k].second);
    return *parts[k];
  };

  std::vector<SegmentResult> results(plan.size());
  std::optional<WorkSharing> own_sharing;
  WorkSharing::Job job;
  job.kind = WorkKind::kMapSegment;
  job.long_units = true;
  if (options.sharing && options.sharing->NumRanks() > 1) {
    // Each rank maps its share of the segments at once, on its threads.
    const int num_ranks = options.sharing->NumRanks();
    const int per_rank = (static_cast<int>(plan.size()) + num_ranks - 1) / num_ranks;
    segment_options.num_threads = std::max(1, options.sharing->NumThreads() / per_rank);
    job.threads_per_unit = segment_options.num_threads;
  } else {
    own_sharing.emplace(nullptr, parallel);
  }
  WorkSharing& sharing = own_sharing ? *own_sharing : *options.sharing;
  job.next = [&](size_t k) { return k < plan.size(); };
  job.compute = [&](size_t k) {
    results[k] = MapPart(part_of(k), segment_options, options.global_mapper,
                         options.remap_doubtful_global, checkpoint_of(k),
                         options.checkpoint_interval_seconds);
  };
  job.request = [&](size_t k, int, ByteWriter& request) {
    request.Put(segment_options);
    request.Put<uint8_t>(options.global_mapper ? 1 : 0);
    if (options.global_mapper) {
      request.Put(*options.global_mapper);
      request.Put<uint8_t>(options.remap_doubtful_global ? 1 : 0);
    }
    request.PutString(checkpoint_of(k).string());
    request.Put(options.checkpoint_interval_seconds);
    PutMapperInput(request, part_of(k));
  };
  job.take_result = [&](size_t k, int, ByteReader& result) {
    results[k] = GetSegmentResult(result, part_of(k));
  };
  job.finish = [&](size_t k) {
    parts[k].reset();
    SegmentReport& report = results[k].report;
    report.first_frame = static_cast<int>(plan[k].first);
    report.num_frames = static_cast<int>(plan[k].second - plan[k].first);
    spdlog::info("segment of frames {}-{}: {} registered in its largest model of {}, {:.1f} s{}",
                 plan[k].first, plan[k].second - 1, report.num_registered, report.num_models,
                 report.seconds,
                 report.resumed            ? " (from its checkpoint)"
                 : report.global_set_aside ? " (its global model set aside, mapped incrementally)"
                                           : "");
  };
  sharing.Run(job);
  LogRankShares("segments: segments", sharing.UnitsPerRank());
  return results;
}

// Stage 2: the segment models merged in capture order, each into the model before it, over
// the input without its loop pairs, `chain` (the overlaps' shared points align them). A merge
// that fails ends a model; the next segment starts another.
std::vector<Reconstruction> MergeSegments(const MapperInput& chain,
                                          const IncrementalMapperOptions& options,
                                          const std::vector<SegmentResult>& results,
                                          SegmentMappingReport* report) {
  Random random(options.seed + 3);
  std::vector<Reconstruction> merged;
  std::unique_ptr<MapperState> dst;
  for (size_t k = 0; k < results.size(); ++k) {
    if (!results[k].model) continue;
    auto src = std::make_unique<MapperState>(chain, options);
    if (src->TakeFramesOf(*results[k].model).size() < 2) continue;
    src->RetriangulateAll();
    src->FilterPoints({});
    if (dst) {
      const ModelMergeReport merge = MergeModels(*dst, *src, random);
      report->segments[k].merged = merge.success;
      report->segments[k].num_merge_inliers = merge.num_inliers;
      if (merge.success) continue;
      spdlog::warn("segments: the segment from frame {} did not merge into the one before ({} "
                   "of {} shared points agree); it starts a model of its own",
                   results[k].report.first_frame, merge.num_inliers, merge.num_correspondences);
      merged.push_back(dst->reconstruction());
    }
    dst = std::move(src);
  }
  if (dst) merged.push_back(dst->reconstruction());
  return merged;
}

}  // namespace

WorkHandler SegmentWorkHandler() {
  return [](ByteReader& request) {
    const auto options = request.Get<IncrementalMapperOptions>();
    std::optional<GlobalMapperOptions> global;
    bool remap_doubtful = false;
    if (request.Get<uint8_t>()) {
      global = request.Get<GlobalMapperOptions>();
      remap_doubtful = request.Get<uint8_t>() != 0;
    }
    const fs::path checkpoint = request.GetString();
    const auto checkpoint_interval_seconds = request.Get<double>();
    auto part = std::make_shared<const MapperInput>(GetMapperInput(request));
    return [options, global, remap_doubtful, checkpoint, checkpoint_interval_seconds,
            part](ByteWriter& result) {
      // On another machine the folder may not be there yet (no shared file system: the
      // checkpoint then stays on this machine, and a rerun maps the segment again).
      if (!checkpoint.empty()) {
        std::error_code ignored;  // MapperCheckpointFile says what is wrong if it is needed
        fs::create_directories(checkpoint.parent_path(), ignored);
      }
      PutSegmentResult(result,
                       MapPart(*part, options, global, remap_doubtful, checkpoint,
                               checkpoint_interval_seconds));
    };
  };
}

std::vector<Reconstruction> MapInSegments(const MapperInput& input,
                                          const IncrementalMapperOptions& mapper_options,
                                          const SegmentMappingOptions& options,
                                          SegmentMappingReport* report,
                                          MapperReport* mapper_report) {
  mapper_options.Check();
  options.Check();
  LOOPSFM_REQUIRE_OPTION(!mapper_options.loop_closure.withhold_loop_pairs,
                         "segment mapping closes the loop pairs at the end already; it does not "
                         "take withhold_loop_pairs");
  SegmentMappingReport local_report;
  MapperReport local_mapper_report;
  if (!report) report = &local_report;
  if (!mapper_report) mapper_report = &local_mapper_report;
  *report = {};
  report->global = options.global_mapper.has_value();

  Timer timer;
  const std::vector<SegmentResult> results = MapSegments(
      input, mapper_options, options,
      PlanSegmentsByCost(TrackedKeypointsPerFrame(input), options.num_segments, options.overlap));
  for (const SegmentResult& result : results) {
    mapper_report->Add(result.mapper_report);
    report->segments.push_back(result.report);
  }
  report->seconds_segments = timer.ElapsedSeconds();

  // Where the merge left frames out (a segment that broke into several models gave only its
  // largest) or several models, the incremental mapper goes on from the merged models over
  // every pair: it registers the frames left and merges the models it can (without closing
  // loops: that comes next, for the whole model).
  timer.Restart();
  const MapperInput chain =
      InputPart(input, 0, input.frames.size(), mapper_options.loop_closure.min_frame_gap);
  std::vector<Reconstruction> chained = MergeSegments(chain, mapper_options, results, report);
  if (chained.size() != 1 || chained[0].NumRegImages() != input.frames.size()) {
    IncrementalMapperOptions extend_options = mapper_options;
    extend_options.loop_closure.method = LoopClosingMethod::kNone;
    chained = ExtendIncrementalModels(input, extend_options, chained, mapper_report);
    report->extended = true;
  }
  report->seconds_merging = timer.ElapsedSeconds();

  timer.Restart();
  std::vector<Reconstruction> models;
  for (const Reconstruction& model : chained) {
    if (static_cast<int>(model.NumRegImages()) < mapper_options.min_model_size) continue;
    models.push_back(CloseLoopsAfterMapping(input, model, mapper_options, mapper_report));
  }
  std::stable_sort(models.begin(), models.end(), [](const auto& a, const auto& b) {
    return a.NumRegImages() > b.NumRegImages();
  });
  report->seconds_loops = timer.ElapsedSeconds();
  mapper_report->num_models = static_cast<int>(models.size());
  mapper_report->num_registered = 0;
  for (const Reconstruction& model : models) {
    mapper_report->num_registered += static_cast<int>(model.NumRegImages());
  }
  const int num_merged = static_cast<int>(std::count_if(
      report->segments.begin(), report->segments.end(), [](const auto& s) { return s.merged; }));
  spdlog::info("segments: {} mapped in {:.1f} s, {} merged into the one before in {:.1f} s; "
               "loops between them and the final refinement {:.1f} s: {} of {} frames in {} "
               "model{}",
               results.size(), report->seconds_segments, num_merged, report->seconds_merging,
               report->seconds_loops, mapper_report->num_registered, input.frames.size(),
               models.size(), models.size() == 1 ? "" : "s");
  return models;
}

}  // namespace loopsfm
