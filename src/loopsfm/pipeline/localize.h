#pragma once
// A pose for every frame (`reconstruct --all-frames`): after mapping, the frames that keyframe
// selection skipped are read again and localised against the models (sfm/frame_localizer.h).
// Their poses go to OUT/localized.txt (model 0's frames, `name tx ty tz qx qy qz qw`,
// camera-to-world) and, through Export, into trajectory.txt, transforms.json and images/
// (the COLMAP model only when asked).

#include <filesystem>
#include <string>
#include <vector>

#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/sfm/frame_localizer.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/util/progress.h"

namespace loopsfm {

struct LocalizedFrame {
  std::string name;
  int source_index = 0;
  LocalizedPose pose;
};

struct LocalizeReport {
  int frames_read = 0;        // frames of the source looked at
  int keyframes = 0;          // of which frames in the database
  int localized = 0;          // of the others, those that got a pose (any model)
  int not_localized = 0;      // those that did not
  double seconds = 0.0;
};

// Reads `input` once, in order; frames stored in `database` are keyframes, the others are
// localised against `models`, tracked forwards from the keyframe before them and, where that
// fails, backwards from the keyframe after them. Returns the localised frames in source
// order.
std::vector<LocalizedFrame> LocalizeSkippedFrames(const std::filesystem::path& input,
                                                  const Database& database,
                                                  const std::vector<Reconstruction>& models,
                                                  const FrameLocalizerOptions& options,
                                                  bool show_progress, const RunHooks* hooks,
                                                  LocalizeReport* report);

// model 0's localised frames as trajectory entries (camera-to-world), in source order.
std::vector<TrajectoryEntry> LocalizedTrajectory(const std::vector<LocalizedFrame>& frames);

}  // namespace loopsfm
