#include "loopsfm/synth/render.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <limits>
#include <optional>
#include <system_error>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// Linear radiance in [0, 1] to an 8-bit value with a display gamma of 2.2.
uchar ToByte(double linear) {
  const double encoded = std::pow(std::clamp(linear, 0.0, 1.0), 1.0 / 2.2);
  return static_cast<uchar>(std::lround(255.0 * encoded));
}

// What the ray through a pixel centre saw, to find the pixels that straddle an edge.
struct CentreSample {
  Eigen::Vector3d rgb = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double distance = 0.0;
  // Which surface (kind, index, and face of a box) was hit; -1 for the sky.
  int surface = -1;

  static CentreSample From(const std::optional<SurfaceHit>& hit, const Eigen::Vector3d& rgb) {
    CentreSample sample;
    sample.rgb = rgb;
    if (!hit) return sample;
    sample.normal = hit->normal;
    sample.distance = hit->distance;
    int face = 0;
    if (hit->kind == SurfaceKind::kBox) {
      for (int axis = 0; axis < 3; ++axis) {
        if (hit->normal[axis] != 0.0) face = 2 * axis + (hit->normal[axis] > 0.0 ? 1 : 0);
      }
    }
    sample.surface = (static_cast<int>(hit->kind) << 24) + 8 * hit->index + face;
    return sample;
  }

  // True where the two samples likely lie on different sides of an edge: different surfaces,
  // a crease (normals more than ~15 degrees apart) or a jump in depth (self-occlusion).
  bool DiffersFrom(const CentreSample& other) const {
    if (surface != other.surface) return true;
    if (surface < 0) return false;
    return normal.dot(other.normal) < 0.966 ||
           std::abs(distance - other.distance) > 0.05 * std::min(distance, other.distance);
  }
};

void CreateDirectory(const std::filesystem::path& path) {
  std::error_code error;
  std::filesystem::create_directories(path, error);
  if (error || !std::filesystem::is_directory(path)) {
    throw StorageError(fmt::format("cannot create output folder '{}': {}; choose a writable path",
                                   path.string(), error ? error.message() : "not a folder"));
  }
}

// True for names SyntheticFrameName makes: frame_NNNNNN.png or frame_NNNNNN.jpg.
bool IsFrameName(const std::string& name) {
  if (name.size() != 16 || name.rfind("frame_", 0) != 0 ||
      (name.substr(12) != ".png" && name.substr(12) != ".jpg")) {
    return false;
  }
  return std::all_of(name.begin() + 6, name.begin() + 12,
                     [](char c) { return c >= '0' && c <= '9'; });
}

// Removes the frames an earlier run left in the output folder (images/frame_NNNNNN.png or
// .jpg, and video.mp4), so that the folder always matches its groundtruth.txt.
void RemoveEarlierFrames(const std::filesystem::path& output_dir) {
  std::error_code error;
  std::filesystem::remove(output_dir / "video.mp4", error);
  const std::filesystem::path images = output_dir / "images";
  if (!std::filesystem::is_directory(images, error)) return;
  std::vector<std::filesystem::path> stale;
  for (const auto& entry : std::filesystem::directory_iterator(images, error)) {
    if (IsFrameName(entry.path().filename().string())) stale.push_back(entry.path());
  }
  for (const auto& path : stale) std::filesystem::remove(path, error);
}

// Opens an mp4 writer with the FFmpeg backend: H.264 ('avc1') where the encoder exists,
// else MPEG-4 part 2 ('mp4v'). Returns the FourCC used.
std::string OpenVideo(const std::filesystem::path& path, const SynthOptions& options,
                      cv::VideoWriter* writer) {
  for (const char* codec : {"avc1", "mp4v"}) {
    const int fourcc = cv::VideoWriter::fourcc(codec[0], codec[1], codec[2], codec[3]);
    if (writer->open(path.string(), cv::CAP_FFMPEG, fourcc, options.fps,
                     cv::Size(options.width, options.height), true) &&
        writer->isOpened()) {
      // SIFT wants few coding artefacts. Backends that support it honour this; OpenCV 4.6's
      // FFmpeg backend ignores it and encodes H.264 at CRF 23 (about 36 dB PSNR here), so
      // stronger artefacts come from the JPEG stage (FrameDegradationOptions::jpeg_quality).
      writer->set(cv::VIDEOWRITER_PROP_QUALITY, 100.0);
      return codec;
    }
  }
  throw StorageError(fmt::format(
      "cannot write video '{}': OpenCV's FFmpeg backend has neither an H.264 ('avc1') nor an "
      "MPEG-4 ('mp4v') encoder; write images instead (no video option) or install an OpenCV "
      "built with FFmpeg",
      path.string()));
}

// Bounds of x / z and y / z (camera axes) over the rays through all points of the image, a
// little wider; nullopt where the lens gives no finite bounds. The lens maps the image
// rectangle continuously and one-to-one, so the extremes lie on the image of its border: that
// is sampled every half pixel, and the bounds are widened by the largest step between two
// samples.
std::optional<Eigen::AlignedBox2d> ImageRayBounds(const Camera& camera) {
  const double w = camera.width, h = camera.height;
  const std::array<Eigen::Vector2d, 5> corners = {Eigen::Vector2d(0.0, 0.0),
                                                  Eigen::Vector2d(w, 0.0), Eigen::Vector2d(w, h),
                                                  Eigen::Vector2d(0.0, h),
                                                  Eigen::Vector2d(0.0, 0.0)};
  Eigen::AlignedBox2d bounds;
  double step = 0.0;
  Eigen::Vector2d last = camera.CamFromImg(corners[0]);
  for (int edge = 0; edge < 4; ++edge) {
    const Eigen::Vector2d from = corners[edge], to = corners[edge + 1];
    const int samples = static_cast<int>(std::ceil(2.0 * (to - from).norm()));
    for (int k = 1; k <= samples; ++k) {
      const Eigen::Vector2d point =
          camera.CamFromImg(from + (to - from) * (static_cast<double>(k) / samples));
      if (!point.allFinite()) return std::nullopt;
      bounds.extend(point);
      step = std::max(step, (point - last).norm());
      last = point;
    }
  }
  const Eigen::Vector2d margin = Eigen::Vector2d::Constant(2.0 * step + 1e-9);
  return Eigen::AlignedBox2d(bounds.min() - margin, bounds.max() + margin);
}

}  // namespace

SyntheticWorld WorldInView(const SyntheticScene& scene, int frame) {
  LOOPSFM_CHECK(frame >= 0 && frame < scene.NumFrames());
  const std::optional<Eigen::AlignedBox2d> bounds = ImageRayBounds(scene.camera);
  if (!bounds) return scene.world;
  // The rays are t (x, y, 1) in camera axes with t > 0 and (x, y) inside the bounds: the
  // pyramid where these four are >= 0. A box whose corners all lie outside one of its faces
  // lies wholly outside it.
  const Eigen::Vector2d lo = bounds->min(), hi = bounds->max();
  auto inside = [&](const Eigen::Vector3d& q) {
    return Eigen::Vector4d(q.x() - lo.x() * q.z(), hi.x() * q.z() - q.x(),
                           q.y() - lo.y() * q.z(), hi.y() * q.z() - q.y());
  };
  const Rigid3d cam_from_world = scene.world_from_cam[frame].Inverse();
  SyntheticWorld world = scene.world;
  world.boxes.clear();
  for (const TexturedBox& box : scene.world.boxes) {
    Eigen::Vector4d most = Eigen::Vector4d::Constant(-std::numeric_limits<double>::infinity());
    for (int corner = 0; corner < 8; ++corner) {
      const Eigen::Vector3d p(corner & 1 ? box.max.x() : box.min.x(),
                              corner & 2 ? box.max.y() : box.min.y(),
                              corner & 4 ? box.max.z() : box.min.z());
      most = most.cwiseMax(inside(cam_from_world * p));
    }
    if ((most.array() >= 0.0).all()) world.boxes.push_back(box);
  }
  return world;
}

cv::Mat RenderFrame(const SyntheticScene& scene, int frame) {
  LOOPSFM_CHECK(frame >= 0 && frame < scene.NumFrames());
  const Camera& camera = scene.camera;
  const int width = camera.width, height = camera.height;
  const int n = scene.options.supersampling;
  const Rigid3d& world_from_cam = scene.world_from_cam[frame];
  // Only the boxes the frame can see: the surfaces hit are the same, at a cost that does not
  // grow with the boxes out of view (a long street).
  const SyntheticWorld world = WorldInView(scene, frame);
  const Eigen::Matrix3d rotation = world_from_cam.rotation.toRotationMatrix();
  const Eigen::Vector3d center = world_from_cam.translation;
  const double pixel_angle = 1.0 / camera.MeanFocalLength();
  // The ray through image point (x, y), unprojected through the camera model (so a lens with
  // distortion renders a distorted frame).
  auto direction = [&](double x, double y) -> Eigen::Vector3d {
    return (rotation * camera.CamFromImg(Eigen::Vector2d(x, y)).homogeneous()).normalized();
  };

  // Pass 1: one ray through every pixel centre.
  std::vector<CentreSample> centres(static_cast<size_t>(width) * height);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const auto& rows) {
    for (int row = rows.begin(); row < rows.end(); ++row) {
      for (int col = 0; col < width; ++col) {
        const Eigen::Vector3d ray = direction(col + 0.5, row + 0.5);
        const std::optional<SurfaceHit> hit = world.CastRay(center, ray);
        centres[static_cast<size_t>(row) * width + col] =
            CentreSample::From(hit, world.Shade(hit, ray, pixel_angle));
      }
    }
  });

  // Pass 2: pixels on a silhouette or crease (where the centre rays of neighbouring pixels
  // see different surfaces) are supersampled with n x n rays spread over the pixel. Texture
  // inside a surface needs no more rays: it is band-limited to the pixel footprint.
  cv::Mat image(height, width, CV_8UC3);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const auto& rows) {
    for (int row = rows.begin(); row < rows.end(); ++row) {
      auto* out = image.ptr<cv::Vec3b>(row);
      for (int col = 0; col < width; ++col) {
        const CentreSample& sample = centres[static_cast<size_t>(row) * width + col];
        bool edge = false;
        for (int dy = -1; dy <= 1 && !edge && n > 1; ++dy) {
          for (int dx = -1; dx <= 1 && !edge; ++dx) {
            const int r = row + dy, c = col + dx;
            if (r < 0 || c < 0 || r >= height || c >= width) continue;
            edge = sample.DiffersFrom(centres[static_cast<size_t>(r) * width + c]);
          }
        }
        Eigen::Vector3d rgb = sample.rgb;
        if (edge) {
          rgb.setZero();
          for (int sy = 0; sy < n; ++sy) {
            for (int sx = 0; sx < n; ++sx) {
              const Eigen::Vector3d ray = direction(col + (sx + 0.5) / n, row + (sy + 0.5) / n);
              rgb += world.Radiance(center, ray, pixel_angle);
            }
          }
          rgb /= n * n;
        }
        out[col] = cv::Vec3b(ToByte(rgb.z()), ToByte(rgb.y()), ToByte(rgb.x()));
      }
    }
  });
  return image;
}

cv::Mat RenderDegradedFrame(const SyntheticScene& scene, int frame) {
  cv::Mat image = RenderFrame(scene, frame);
  const FrameDegradationOptions& degradation = scene.options.degradation;
  const bool blurred =
      std::any_of(degradation.motion_blur.begin(), degradation.motion_blur.end(),
                  [frame](const BlurRange& blur) { return blur.frames.Contains(frame); });
  const Eigen::Vector2d motion = blurred ? ImageMotion(scene, frame) : Eigen::Vector2d::Zero();
  DegradeFrame(degradation, frame, motion, scene.options.seed, &image);
  return image;
}

SynthReport RenderSyntheticScene(const SynthOptions& options,
                                 const std::filesystem::path& output_dir,
                                 const SynthProgressCallback& progress) {
  const Timer timer;
  const SyntheticScene scene = MakeScene(options);
  CreateDirectory(output_dir);
  RemoveEarlierFrames(output_dir);
  SynthReport report;
  report.output = output_dir;
  report.num_frames = scene.NumFrames();
  report.groundtruth = output_dir / "groundtruth.txt";
  report.intrinsics = output_dir / "intrinsics.txt";
  WriteIntrinsicsFile(report.intrinsics, scene.camera);
  WriteTrajectoryFile(report.groundtruth, GroundTruthTrajectory(scene));

  cv::VideoWriter video;
  if (options.video) {
    report.frames = output_dir / "video.mp4";
    report.video_codec = OpenVideo(report.frames, options, &video);
  } else {
    report.frames = output_dir / "images";
    CreateDirectory(report.frames);
  }
  const int jpeg_quality = options.degradation.jpeg_quality;
  auto write_frame = [&](const cv::Mat& image, int frame) {
    if (options.video) {
      video.write(jpeg_quality > 0 ? JpegRoundTrip(image, jpeg_quality) : image);
      return;
    }
    const std::filesystem::path path = report.frames / SyntheticFrameName(options, frame);
    bool written = false;
    if (jpeg_quality > 0) {
      const std::vector<uchar> bytes = EncodeJpeg(image, jpeg_quality);
      std::ofstream file(path, std::ios::binary);
      file.write(reinterpret_cast<const char*>(bytes.data()),
                 static_cast<std::streamsize>(bytes.size()));
      written = static_cast<bool>(file);
    } else {
      written = cv::imwrite(path.string(), image);
    }
    if (!written) {
      throw StorageError(fmt::format("cannot write image '{}'; check the disk and permissions",
                                     path.string()));
    }
  };

  // Frame i is encoded and written while frame i + 1 renders; at most two frames are in memory.
  tbb::task_group writer;
  for (int frame = 0; frame < scene.NumFrames(); ++frame) {
    const Timer render_timer;
    cv::Mat image = RenderDegradedFrame(scene, frame);
    report.render_seconds += render_timer.ElapsedSeconds();
    writer.wait();  // rethrows a failed write of the previous frame
    if (frame > 0 && progress) progress(frame, scene.NumFrames());
    writer.run([&write_frame, image = std::move(image), frame] { write_frame(image, frame); });
  }
  writer.wait();
  if (options.video) {
    video.release();
    std::error_code error;
    if (std::filesystem::file_size(report.frames, error) == 0 || error) {
      throw StorageError(fmt::format("writing video '{}' failed (the file is missing or empty); "
                                     "check the disk, or write images instead",
                                     report.frames.string()));
    }
  }
  if (progress) progress(scene.NumFrames(), scene.NumFrames());
  report.seconds = timer.ElapsedSeconds();
  return report;
}

}  // namespace loopsfm
