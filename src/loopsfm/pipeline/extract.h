#pragma once
// The frames + features stage: decode a video or image folder, keep keyframes, extract SIFT
// in parallel (on this process's threads and on the other ranks of an MPI run) and store
// frames, cameras and features in the database, in frame order. Frames are streamed through
// a bounded window, so memory does not grow with the number of frames. Frames
// already stored with features are skipped, so an interrupted run resumes.

#include <filesystem>
#include <functional>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include "loopsfm/feature/sift.h"
#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/scene/camera.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/video/keyframes.h"
#include "loopsfm/util/progress.h"

namespace loopsfm {

struct ExtractOptions {
  // Which frames to keep.
  KeyframeOptions keyframes;
  // Detector and descriptor settings.
  SiftOptions sift;
  // Known intrinsics (from --intrinsics); without them a camera of camera_model is guessed
  // per image size (self-calibration estimates its focal length before mapping).
  std::optional<Camera> intrinsics;
  CameraModelId camera_model = CameraModelId::kSimpleRadial;
  // Worker threads for feature extraction (0: all cores).
  int num_threads = 0;
  // The ranks of an MPI run to share the frames with (null: this process alone).
  WorkSharing* sharing = nullptr;
  // Show progress on stderr.
  bool show_progress = true;
  // Who follows the progress and may ask the run to stop (null: nobody); must outlive the
  // run. The stages of a reconstruction get the reconstruction's.
  const RunHooks* hooks = nullptr;
  void Check() const;
};

struct ExtractReport {
  int frames_read = 0;         // frames of the source looked at (adaptive keyframes)
  int frames_blurred = 0;      // of which judged blurred (adaptive keyframes)
  int frames_decoded = 0;      // keyframes taken from the source
  int frames_extracted = 0;    // of which features were extracted now
  int frames_resumed = 0;      // of which were already in the database
  int unreadable_images = 0;   // folder images that could not be read
  int num_cameras = 0;
  size_t num_features = 0;     // over the frames extracted now
  double seconds = 0.0;
  // Of which decoding and choosing keyframes (one thread, on rank 0 of an MPI run).
  double decode_seconds = 0.0;
  // Frames extracted by each rank of an MPI run (rank 0 first; one entry in one process).
  std::vector<size_t> frames_per_rank;
  double FeaturesPerFrame() const {
    return frames_extracted ? double(num_features) / frames_extracted : 0.0;
  }
  double FramesPerSecond() const { return seconds > 0 ? frames_extracted / seconds : 0.0; }
};

ExtractReport ExtractFeatures(const std::filesystem::path& input, Database& database,
                              const ExtractOptions& options);

// The report as JSON (for benchmarks and scripts).
nlohmann::json ToJson(const ExtractReport& report);

// A worker rank's part of ExtractFeatures: SIFT on the frames rank 0 sends.
WorkHandler SiftWorkHandler();

// Extracts the frames of `input` at the given source indices (frames between keyframes) and
// stores them as fill-ins (KeyframeReason::kFillIn), with the cameras and SIFT options of
// ExtractFeatures. Throws InputError when a frame cannot be read (the source changed).
ExtractReport ExtractFillInFrames(const std::filesystem::path& input, Database& database,
                                  const ExtractOptions& options,
                                  const std::vector<int>& source_indices);

}  // namespace loopsfm
