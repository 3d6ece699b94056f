#pragma once
// Frame sources: a video file (decoded by OpenCV's FFmpeg backend) or an ordered folder
// of images. Frames are streamed one at a time, never all held in memory.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

namespace loopsfm {

struct RawFrame {
  // Index in the source (frame number in the video, position in the sorted folder).
  int source_index = 0;
  // "frame_%06d.png" for video frames, the file name for folder images.
  std::string name;
  // 8-bit BGR image.
  cv::Mat image;
};

enum class SourceKind { kVideo, kImageFolder };

struct FrameSourceInfo {
  SourceKind kind = SourceKind::kVideo;
  std::filesystem::path path;
  // Frames the source says it holds (for a video, the container's frame count, which can
  // be an estimate; for a folder, the number of image files).
  int expected_frames = 0;
  double fps = 0.0;
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // The next frame, or nullopt at the end. Unreadable folder images are skipped (with a
  // warning) and counted in NumSkipped().
  virtual std::optional<RawFrame> Next() = 0;
  // Skips the next frame without decoding it fully where the format allows; false at the end.
  virtual bool Skip() = 0;
  virtual int NumSkipped() const { return 0; }
  const FrameSourceInfo& Info() const { return info_; }

 protected:
  FrameSourceInfo info_;
};

// Opens a video file or an image folder. Throws InputError with what was wrong and what to
// do when the path is missing, is a single image, is not a decodable video, or a folder holds
// no images.
std::unique_ptr<FrameSource> OpenFrameSource(const std::filesystem::path& path);

// Name of video frame k, joinable with ground truth files.
std::string VideoFrameName(int index);

// True for file names with an image extension we read (jpg, jpeg, png, tif, tiff, bmp).
bool HasImageExtension(const std::filesystem::path& path);

}  // namespace loopsfm
