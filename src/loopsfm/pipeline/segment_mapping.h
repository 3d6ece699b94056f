#pragma once
// Mapping a long video in segments: its frames, in capture order, are cut into overlapping
// segments; each segment is mapped on its own by the incremental mapper with loop closing
// (loop/loop_closing.h), several at once; then the segment models are merged one after the
// other by the similarity their shared frames' points give (sfm/model_merger.h); where that
// leaves frames out or several models, the incremental mapper goes on from the merged models
// (ExtendIncrementalModels); last, the loops between segments are closed on the merged model
// with the Sim3 pose graph and a global bundle adjustment (CloseLoopsAfterMapping).
//
// Segments bound the cost of a registration by the segment's size, and they are what
// several processes can map apart. The merge chain sees only the pairs between frames fewer
// than loop_closure.min_frame_gap apart (the overlaps tie the segments together); the loop
// pairs come back for the loop closing at the end, as with withheld loop pairs. A merge that
// fails (too few shared points agree) starts a new model with the next segment.
//
//   SegmentMappingOptions segments;
//   segments.num_segments = 4;
//   std::vector<Reconstruction> models =
//       MapInSegments(input, mapper_options, segments, &report, &mapper_report);

#include <filesystem>
#include <optional>
#include <utility>
#include <vector>

#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/sfm/global_mapper_options.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

struct SegmentMappingOptions {
  // Segments the frames are cut into (1: the whole video at once, no segments).
  int num_segments = 1;
  // Frames each segment shares with the next, in capture order (of the frames the mapper
  // gets, the keyframes); at least 2.
  int overlap = 20;
  // Segments mapped at once, each with its share of the mapper's threads (0: as many as the
  // mapper has threads).
  int num_parallel = 0;
  // Where set, each segment's mapping state is saved to checkpoint_dir/segment_K.bin (K its
  // index) every checkpoint_interval_seconds and when it has finished (the mapper's
  // checkpoint, pipeline/mapper_checkpoint.h, over the segment's frames), and a rerun goes on
  // from there: a finished segment is not mapped again. Empty: no checkpoints.
  std::filesystem::path checkpoint_dir;
  double checkpoint_interval_seconds = 60.0;
  // Where set, each segment is mapped by the global mapper with these options instead of the
  // incremental one (the merge, the frames a segment left out and the loops between segments
  // are still the incremental mapper's work). Such segments have no checkpoints.
  std::optional<GlobalMapperOptions> global_mapper;
  // With global_mapper: a segment whose global model is doubtful (likely bent or broken,
  // GlobalMapperReport::Doubtful) is mapped again by the incremental mapper; false: kept.
  bool remap_doubtful_global = true;
  // The ranks of an MPI run to share the segments with (null: this process alone). The
  // checkpoint folder must then be one they all reach (a shared file system).
  WorkSharing* sharing = nullptr;
  void Check() const;  // throws InvalidArgument
};

struct SegmentReport {
  // The segment's frames in capture order: [first_frame, first_frame + num_frames).
  int first_frame = 0;
  int num_frames = 0;
  // Frames in its largest model (the one merged), and the models it made.
  int num_registered = 0;
  int num_models = 0;
  int num_loops_closed = 0;
  double seconds = 0.0;
  // Taken from the checkpoint of a run before, which had finished it.
  bool resumed = false;
  // Its global model was doubtful and set aside, and the incremental mapper mapped it.
  bool global_set_aside = false;
  // Merged into the model of the segment before (false for the first, and where the merge
  // failed or this segment made no model).
  bool merged = false;
  int num_merge_inliers = 0;
};

struct SegmentMappingReport {
  std::vector<SegmentReport> segments;
  // The segments were mapped by the global mapper.
  bool global = false;
  // The merge left frames out or several models, and the incremental mapper went on from
  // them (part of the merging time).
  bool extended = false;
  // Wall-clock time of the three stages: mapping the segments (at once), merging them, and
  // closing the loops between them with the final refinement.
  double seconds_segments = 0.0;
  double seconds_merging = 0.0;
  double seconds_loops = 0.0;
};

// A worker rank's part of MapInSegments: mapping the segments rank 0 sends.
WorkHandler SegmentWorkHandler();

// The segments, as [begin, end) capture indices: num_segments of equal length (to one frame)
// that share `overlap` frames with the next, covering the frames. Fewer when a segment would
// have fewer than 2 * overlap frames (the log says so); one for num_segments 1.
std::vector<std::pair<size_t, size_t>> PlanSegments(size_t num_frames, int num_segments,
                                                    int overlap);
// As many segments as PlanSegments(frame_costs.size(), ...) makes, sharing `overlap` frames
// with the next, each of at least 2 * overlap frames, cut so that the most costly segment
// costs as little as can be: the sum of its frames' costs, its overlaps included. With equal
// costs, PlanSegments' segments. MapInSegments weighs a frame by its keypoints in tracks (a
// segment's mapping time follows the observations its bundles hold).
std::vector<std::pair<size_t, size_t>> PlanSegmentsByCost(const std::vector<double>& frame_costs,
                                                          int num_segments, int overlap);

// The models, largest first, as the incremental mapper's (at least min_model_size frames).
// `mapper_report` gets every segment's counts and times (MapperReport::Add), then the loop
// closing's; num_models and num_registered describe the models returned. InvalidArgument
// for bad options and for withhold_loop_pairs (segments already map without the loop
// pairs).
std::vector<Reconstruction> MapInSegments(const MapperInput& input,
                                          const IncrementalMapperOptions& mapper_options,
                                          const SegmentMappingOptions& options,
                                          SegmentMappingReport* report,
                                          MapperReport* mapper_report);

}  // namespace loopsfm
