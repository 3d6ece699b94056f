#include "loopsfm/loop/loop_closing.h"

#include <vector>

#include "loopsfm/loop/loop_closure.h"
#include "loopsfm/loop/track_split.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

namespace {

// Loop closing as the mapper's hook: the pose-graph loop closer after each registration,
// the split tracks of the largest model at the end.
class LoopClosingHook : public MapperHook {
 public:
  LoopClosingHook(const MapperInput& input, const IncrementalMapperOptions& options)
      : options_(options), closer_(input, options.loop_closure, options.seed + 1) {}

  bool AfterRegistration(MapperState& model, image_t image_id, MapperReport* report) override {
    return options_.loop_closure.CloseWhileMapping() &&
           closer_.AfterRegistration(model, image_id, report);
  }

  void AfterMapping(MapperState& largest, MapperReport* report) override {
    if (!options_.loop_closure.SplitTracks()) return;
    Random random(options_.seed + 2);
    CloseLoopsBySplitTracks(largest, options_.loop_closure, random, report);
  }

  void Save(MapperCheckpoint* checkpoint) const override { closer_.Save(checkpoint); }
  void Restore(const MapperCheckpoint& checkpoint) override { closer_.Restore(checkpoint); }

 private:
  const IncrementalMapperOptions& options_;
  LoopCloser closer_;
};

std::vector<Reconstruction> Map(const MapperInput& input, const IncrementalMapperOptions& options,
                                MapperReport* report, const MapperProgress& progress,
                                const MapperCheckpointing& checkpointing) {
  LoopClosingHook hook(input, options);
  return RunIncrementalMapper(input, options, report, progress, checkpointing, &hook);
}

}  // namespace

MapperInput WithoutLoopPairs(const MapperInput& input, int min_frame_gap) {
  return InputPart(input, 0, input.frames.size(), min_frame_gap);
}

Reconstruction CloseLoopsAfterMapping(const MapperInput& input, const Reconstruction& model,
                                      const IncrementalMapperOptions& options,
                                      MapperReport* report) {
  Timer timer;
  MapperState state(input, options);
  Reconstruction& rec = state.reconstruction();
  const std::vector<image_t> ordered = state.TakeFramesOf(model);
  if (ordered.size() < 2) return model;
  // The model's points, where loop pairs cannot have joined their tracks to others (those
  // are triangulated again, their loops' two ends getting points of their own where they
  // disagree); then every track, for the observations left free and the points of one track
  // that agree now.
  state.TakePointsOf(model, options.loop_closure.min_frame_gap);
  state.RetriangulateAll();
  const double seconds_triangulation = timer.ElapsedSeconds();
  report->seconds_triangulation += seconds_triangulation;
  const LoopClosureOptions& loop = options.loop_closure;
  bool corrected = false;
  if (loop.CloseWhileMapping()) {
    LoopCloser closer(input, loop, options.seed + 1, /*refine=*/false);
    for (image_t id : ordered) closer.AfterRegistration(state, id, report);
    corrected = closer.CloseGathered(state, report);
  }
  // Split tracks start from a refined map after the pose graph, from the map as triangulated
  // without it; their pass ends with a bundle of its own.
  if (corrected) {
    state.RefineAfterCorrection(report, loop.refine_function_tolerance);
  } else if (!loop.SplitTracks() || loop.CloseWhileMapping()) {
    state.GlobalRefinement(report);
  }
  if (loop.SplitTracks()) {
    Random split_random(options.seed + 2);
    const int tied = CloseLoopsBySplitTracks(state, loop, split_random, report);
    if (tied == 0 && !loop.CloseWhileMapping()) state.GlobalRefinement(report);
  }
  spdlog::info("loop pairs added after mapping: {} loops closed, {:.1f} s",
               report->loops_closed.size(), timer.ElapsedSeconds());
  return rec;
}

std::vector<Reconstruction> MapWithLoopClosing(const MapperInput& input,
                                               const IncrementalMapperOptions& options,
                                               MapperReport* report,
                                               const MapperProgress& progress,
                                               const MapperCheckpointing& checkpointing) {
  options.Check();
  MapperReport local;
  MapperReport* out = report ? report : &local;
  if (!options.loop_closure.withhold_loop_pairs) {
    return Map(input, options, out, progress, checkpointing);
  }
  const MapperInput withheld = WithoutLoopPairs(input, options.loop_closure.min_frame_gap);
  spdlog::info("mapper: {} loop pairs withheld until the end ({} pairs, {} tracks left)",
               input.pairs.size() - withheld.pairs.size(), withheld.pairs.size(),
               withheld.tracks.size());
  IncrementalMapperOptions mapping = options;
  mapping.loop_closure.withhold_loop_pairs = false;
  mapping.loop_closure.method = LoopClosingMethod::kNone;  // no loop pairs to close yet
  std::vector<Reconstruction> models = Map(withheld, mapping, out, progress, checkpointing);
  if (!models.empty()) models[0] = CloseLoopsAfterMapping(input, models[0], options, out);
  return models;
}

}  // namespace loopsfm
