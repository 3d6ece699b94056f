#include "loopsfm/video/frame_source.h"

#include <algorithm>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm {
namespace fs = std::filesystem;

namespace {

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

class VideoSource : public FrameSource {
 public:
  explicit VideoSource(const fs::path& path) {
    capture_.open(path.string(), cv::CAP_FFMPEG);
    if (!capture_.isOpened()) {
      throw InputError(fmt::format(
          "cannot decode '{}' as a video: it is not a format FFmpeg reads (mp4, mov, mkv, avi), "
          "or the file is damaged; convert it with ffmpeg or pass a folder of images",
          path.string()));
    }
    // Phones store portrait video as landscape frames plus a rotation flag: frames are
    // turned upright, so the camera's width and height are the displayed ones.
    capture_.set(cv::CAP_PROP_ORIENTATION_AUTO, 1.0);
    info_.kind = SourceKind::kVideo;
    info_.path = path;
    info_.expected_frames = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_COUNT));
    info_.fps = capture_.get(cv::CAP_PROP_FPS);
  }

  std::optional<RawFrame> Next() override {
    RawFrame frame;
    // A damaged packet fails one read; the decoder may still hold frames after it, so a few
    // more reads are tried before the video counts as ended.
    bool ok = false;
    for (int attempt = 0; attempt < kMaxFailedReads && !ok; ++attempt) {
      ok = capture_.read(frame.image) && !frame.image.empty();
    }
    if (!ok) return End();
    if (frame.image.channels() == 1) cv::cvtColor(frame.image, frame.image, cv::COLOR_GRAY2BGR);
    // The decoder's position (from timestamps) names the frame, so a frame lost to damage
    // does not shift the names of the frames after it.
    const int position = static_cast<int>(capture_.get(cv::CAP_PROP_POS_FRAMES)) - 1;
    if (position >= next_index_) next_index_ = position;
    frame.source_index = next_index_++;
    frame.name = VideoFrameName(frame.source_index);
    return frame;
  }

  bool Skip() override {
    if (!capture_.grab()) {
      End();
      return false;
    }
    ++next_index_;
    return true;
  }

 private:
  std::optional<RawFrame> End() {
    if (next_index_ == 0) {
      throw InputError(fmt::format(
          "'{}' opened as a video but no frame could be decoded; the file may be truncated or "
          "use a codec FFmpeg cannot decode",
          info_.path.string()));
    }
    if (!warned_ && info_.expected_frames > 0 && next_index_ < info_.expected_frames - 1) {
      spdlog::warn("video '{}' ended after {} of {} frames; it may be truncated or corrupt",
                   info_.path.string(), next_index_, info_.expected_frames);
    }
    warned_ = true;
    return std::nullopt;
  }

  static constexpr int kMaxFailedReads = 8;
  cv::VideoCapture capture_;
  int next_index_ = 0;
  bool warned_ = false;
};

class ImageFolderSource : public FrameSource {
 public:
  explicit ImageFolderSource(const fs::path& path) {
    for (const auto& entry : fs::directory_iterator(path)) {
      if (entry.is_regular_file() && HasImageExtension(entry.path())) files_.push_back(entry.path());
    }
    if (files_.empty()) {
      throw InputError(fmt::format(
          "folder '{}' holds no images (looked for .jpg, .jpeg, .png, .tif, .tiff, .bmp); point "
          "loopsfm at the folder that holds the frames",
          path.string()));
    }
    std::sort(files_.begin(), files_.end(),
              [](const fs::path& a, const fs::path& b) { return a.filename() < b.filename(); });
    info_.kind = SourceKind::kImageFolder;
    info_.path = path;
    info_.expected_frames = static_cast<int>(files_.size());
  }

  std::optional<RawFrame> Next() override {
    while (next_ < files_.size()) {
      const size_t index = next_++;
      RawFrame frame;
      frame.image = cv::imread(files_[index].string(), cv::IMREAD_COLOR);
      if (frame.image.empty()) {
        ++skipped_;
        spdlog::warn("skipping '{}': not a readable image", files_[index].string());
        continue;
      }
      frame.source_index = static_cast<int>(index);
      frame.name = files_[index].filename().string();
      return frame;
    }
    return std::nullopt;
  }

  bool Skip() override {
    if (next_ >= files_.size()) return false;
    ++next_;
    return true;
  }

  int NumSkipped() const override { return skipped_; }

 private:
  std::vector<fs::path> files_;
  size_t next_ = 0;
  int skipped_ = 0;
};

}  // namespace

std::string VideoFrameName(int index) { return fmt::format("frame_{:06d}.png", index); }

bool HasImageExtension(const fs::path& path) {
  const std::string ext = Lower(path.extension().string());
  return ext == ".jpg" || ext == ".jpeg" || ext == ".png" || ext == ".tif" || ext == ".tiff" ||
         ext == ".bmp";
}

std::unique_ptr<FrameSource> OpenFrameSource(const fs::path& path) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (ec || !fs::exists(status)) {
    throw InputError(fmt::format("input '{}' does not exist; pass a video file or a folder of images",
                                 path.string()));
  }
  if (fs::is_directory(status)) return std::make_unique<ImageFolderSource>(path);
  if (!fs::is_regular_file(status)) {
    throw InputError(fmt::format("input '{}' is neither a video file nor a folder", path.string()));
  }
  if (HasImageExtension(path)) {
    throw InputError(fmt::format(
        "input '{}' is a single image; pass the folder that holds the frames instead",
        path.string()));
  }
  return std::make_unique<VideoSource>(path);
}

}  // namespace loopsfm
