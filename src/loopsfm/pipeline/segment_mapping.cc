#include "loopsfm/pipeline/segment_mapping.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <memory>
#include <optional>
#include <thread>

#include "loopsfm/loop/loop_closing.h"
#include "loopsfm/pipeline/mapper_checkpoint.h"
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

namespace {

struct SegmentResult {
  std::optional<Reconstruction> model;  // the largest
  MapperReport mapper_report;
  SegmentReport report;
};

// Maps frames [begin, end) of the input; with a checkpoint path, saves the mapping state
// there now and then, and goes on from what is there.
SegmentResult MapSegment(const MapperInput& input, const IncrementalMapperOptions& options,
                         size_t begin, size_t end, const fs::path& checkpoint_path,
                         double checkpoint_interval_seconds) {
  Timer timer;
  SegmentResult result;
  result.report.first_frame = static_cast<int>(begin);
  result.report.num_frames = static_cast<int>(end - begin);
  const MapperInput part = InputPart(input, begin, end);
  std::optional<MapperCheckpointFile> checkpoint;
  if (!checkpoint_path.empty()) {
    checkpoint.emplace(checkpoint_path, part, options, checkpoint_interval_seconds);
    result.report.resumed = checkpoint->Finished();
  }
  std::vector<Reconstruction> models =
      MapWithLoopClosing(part, options, &result.mapper_report, {},
                         checkpoint ? checkpoint->checkpointing() : MapperCheckpointing{});
  result.report.num_models = static_cast<int>(models.size());
  result.report.num_loops_closed = static_cast<int>(result.mapper_report.loops_closed.size());
  if (!models.empty()) {
    result.report.num_registered = static_cast<int>(models[0].NumRegImages());
    result.model = std::move(models[0]);
  }
  result.report.seconds = timer.ElapsedSeconds();
  spdlog::info("segment of frames {}-{}: {} registered in its largest model of {}, {:.1f} s{}",
               begin, end - 1, result.report.num_registered, result.report.num_models,
               result.report.seconds, result.report.resumed ? " (from its checkpoint)" : "");
  return result;
}

// Stage 1: every segment mapped, num_parallel at a time, each with its share of the threads.
// An exception in one segment is thrown again once all have finished.
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
  std::vector<SegmentResult> results(plan.size());
  std::vector<std::exception_ptr> errors(plan.size());
  if (!options.checkpoint_dir.empty()) {
    std::error_code ec;
    fs::create_directories(options.checkpoint_dir, ec);
    if (ec) {
      throw StorageError(fmt::format("cannot create the segment checkpoint folder '{}': {}",
                                     options.checkpoint_dir.string(), ec.message()));
    }
  }
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t k = next++; k < plan.size(); k = next++) {
      try {
        const fs::path checkpoint =
            options.checkpoint_dir.empty()
                ? fs::path()
                : options.checkpoint_dir / fmt::format("segment_{}.bin", k);
        results[k] = MapSegment(input, segment_options, plan[k].first, plan[k].second,
                                checkpoint, options.checkpoint_interval_seconds);
      } catch (...) {
        errors[k] = std::current_exception();
      }
    }
  };
  std::vector<std::thread> workers;
  for (int t = 1; t < parallel; ++t) workers.emplace_back(work);
  work();
  for (std::thread& worker : workers) worker.join();
  for (const std::exception_ptr& error : errors) {
    if (error) std::rethrow_exception(error);
  }
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

  Timer timer;
  const std::vector<SegmentResult> results = MapSegments(
      input, mapper_options, options,
      PlanSegments(input.frames.size(), options.num_segments, options.overlap));
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
