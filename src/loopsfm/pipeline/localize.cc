#include "loopsfm/pipeline/localize.h"

#include <unordered_map>

#include "loopsfm/util/progress.h"
#include "loopsfm/util/timer.h"
#include "loopsfm/video/frame_source.h"

namespace loopsfm {

std::vector<LocalizedFrame> LocalizeSkippedFrames(const std::filesystem::path& input,
                                                  const Database& database,
                                                  const std::vector<Reconstruction>& models,
                                                  const FrameLocalizerOptions& options,
                                                  bool show_progress, LocalizeReport* report) {
  Timer timer;
  *report = LocalizeReport();
  std::unordered_map<std::string, image_t> keyframes;
  for (const Frame& frame : database.ReadFrames()) keyframes[frame.name] = frame.image_id;
  std::unique_ptr<FrameSource> source = OpenFrameSource(input);
  Progress progress("localise", std::max(0, source->Info().expected_frames), show_progress);
  FrameLocalizer localizer(models, options);
  std::vector<LocalizedFrame> localized;
  while (std::optional<RawFrame> frame = source->Next()) {
    ++report->frames_read;
    progress.Advance();
    if (const auto it = keyframes.find(frame->name); it != keyframes.end()) {
      ++report->keyframes;
      localizer.AddKeyframe(it->second, frame->image);
      continue;
    }
    if (std::optional<LocalizedPose> pose = localizer.Localize(frame->image)) {
      localized.push_back({frame->name, frame->source_index, *pose});
      ++report->localized;
    } else {
      ++report->not_localized;
    }
  }
  progress.Finish();
  report->seconds = timer.ElapsedSeconds();
  return localized;
}

std::vector<TrajectoryEntry> LocalizedTrajectory(const std::vector<LocalizedFrame>& frames) {
  std::vector<TrajectoryEntry> entries;
  for (const LocalizedFrame& frame : frames) {
    if (frame.pose.model != 0) continue;
    entries.push_back({frame.name, frame.pose.cam_from_world.Inverse()});
  }
  return entries;
}

}  // namespace loopsfm
