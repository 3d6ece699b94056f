#pragma once
// Rendering synthetic scenes (see synthetic_scene.h) with a CPU ray caster, one frame at a
// time, to an image folder or a video, with the ground truth beside them:
//
//   OUTPUT/images/frame_%06d.png   (or OUTPUT/video.mp4 with SynthOptions::video; .jpg with
//                                   a JPEG quality set)
//   OUTPUT/groundtruth.txt         name tx ty tz qx qy qz qw per frame, world_from_cam
//   OUTPUT/intrinsics.txt          PINHOLE width height fx fy cx cy (or the lens's model and
//                                   parameters, SynthOptions::lens)

#include <filesystem>
#include <functional>
#include <string>

#include <opencv2/core.hpp>

#include "loopsfm/synth/synthetic_scene.h"

namespace loopsfm {

// The scene's world without the boxes no ray through the image of `frame` can hit (those
// wholly outside the pyramid of its rays); the other boxes keep their order, so every ray of
// the frame hits the same surface as in the whole world (box indices aside).
SyntheticWorld WorldInView(const SyntheticScene& scene, int frame);

// Renders one frame as an 8-bit BGR image of the camera's size. Rows are rendered in
// parallel (TBB); the result does not depend on the thread count. Only the boxes of
// WorldInView are tested, so the cost does not grow with the boxes out of view.
cv::Mat RenderFrame(const SyntheticScene& scene, int frame);

// RenderFrame with the degradations of scene.options.degradation that cover the frame (motion
// blur along ImageMotion, low texture, darkness, sensor noise); the JPEG stage is applied when
// the frame is written. Equals RenderFrame when no degradation is set.
cv::Mat RenderDegradedFrame(const SyntheticScene& scene, int frame);

struct SynthReport {
  // The output folder.
  std::filesystem::path output;
  // images/ folder, or video.mp4 when a video was written.
  std::filesystem::path frames;
  std::filesystem::path groundtruth;
  std::filesystem::path intrinsics;
  int num_frames = 0;
  // FourCC of the video codec used ("avc1" or "mp4v"); empty for images.
  std::string video_codec;
  // Wall-clock seconds in all, and of that spent rendering (the rest is encoding and I/O).
  double seconds = 0.0;
  double render_seconds = 0.0;
};

// Called after each frame is written with (frames done, frames in all). An exception thrown
// from it (e.g. Cancelled) stops the rendering; the frames written so far stay on disk.
using SynthProgressCallback = std::function<void(int, int)>;

// Renders all frames of the scene chosen by `options` into `output_dir` (created if needed),
// streaming frames to disk one at a time; frames of an earlier run there (frame_NNNNNN.png or
// .jpg, video.mp4) are removed first. Throws InvalidArgument for bad options and StorageError when
// the output cannot be written (or no mp4 encoder is available).
SynthReport RenderSyntheticScene(const SynthOptions& options,
                                 const std::filesystem::path& output_dir,
                                 const SynthProgressCallback& progress = {});

}  // namespace loopsfm
