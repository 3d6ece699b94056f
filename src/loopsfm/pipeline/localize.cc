#include "loopsfm/pipeline/localize.h"

#include <algorithm>
#include <unordered_map>

#include <opencv2/imgproc.hpp>

#include "loopsfm/util/progress.h"
#include "loopsfm/util/timer.h"
#include "loopsfm/video/frame_source.h"

namespace loopsfm {

std::vector<LocalizedFrame> LocalizeSkippedFrames(const std::filesystem::path& input,
                                                  const Database& database,
                                                  const std::vector<Reconstruction>& models,
                                                  const FrameLocalizerOptions& options,
                                                  bool show_progress, const RunHooks* hooks,
                                                  LocalizeReport* report) {
  Timer timer;
  *report = LocalizeReport();
  std::unordered_map<std::string, image_t> keyframes;
  for (const Frame& frame : database.ReadFrames()) keyframes[frame.name] = frame.image_id;
  std::unique_ptr<FrameSource> source = OpenFrameSource(input);
  Progress progress("localise", std::max(0, source->Info().expected_frames), show_progress,
                    hooks);
  FrameLocalizer localizer(models, options);
  std::vector<LocalizedFrame> localized;
  // The frames since the last keyframe (grey, in their own pixels), for a second try
  // backwards from the next keyframe when tracking forwards lost a frame (a blurred stretch
  // loses the points on its way in, not the way back); bounded in bytes.
  struct Between {
    RawFrame frame;  // image: grey
    bool has_pose = false;
  };
  std::vector<Between> between;
  size_t between_bytes = 0;
  bool between_complete = true;
  auto backwards = [&](image_t keyframe_id, const cv::Mat& keyframe_image) {
    const bool any_missing = std::any_of(between.begin(), between.end(),
                                         [](const Between& b) { return !b.has_pose; });
    if (!any_missing || !between_complete) return;
    FrameLocalizer back(models, options);
    back.AddKeyframe(keyframe_id, keyframe_image);
    for (auto it = between.rbegin(); it != between.rend(); ++it) {
      std::optional<LocalizedPose> pose = back.Localize(it->frame.image);
      if (it->has_pose || !pose) continue;
      localized.push_back({it->frame.name, it->frame.source_index, *pose});
      ++report->localized;
      --report->not_localized;
    }
  };
  while (std::optional<RawFrame> frame = source->Next()) {
    ++report->frames_read;
    progress.Advance();
    if (const auto it = keyframes.find(frame->name); it != keyframes.end()) {
      ++report->keyframes;
      backwards(it->second, frame->image);
      between.clear();
      between_bytes = 0;
      between_complete = true;
      localizer.AddKeyframe(it->second, frame->image);
      continue;
    }
    std::optional<LocalizedPose> pose = localizer.Localize(frame->image);
    if (pose) {
      localized.push_back({frame->name, frame->source_index, *pose});
      ++report->localized;
    } else {
      ++report->not_localized;
    }
    if (between_complete) {
      cv::Mat grey;
      cv::cvtColor(frame->image, grey, cv::COLOR_BGR2GRAY);
      between_bytes += grey.total();
      between_complete = between_bytes <= options.max_buffered_bytes;
      if (between_complete) {
        between.push_back({RawFrame{frame->source_index, frame->name, grey}, pose.has_value()});
      } else {
        between.clear();
      }
    }
  }
  progress.Finish();
  std::sort(localized.begin(), localized.end(),
            [](const LocalizedFrame& a, const LocalizedFrame& b) {
              return a.source_index < b.source_index;
            });
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
