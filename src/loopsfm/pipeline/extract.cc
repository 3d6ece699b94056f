#include "loopsfm/pipeline/extract.h"
#include "loopsfm/pipeline/fingerprint.h"

#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <unordered_set>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <tbb/parallel_for.h>

#include "loopsfm/pipeline/wire_format.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/progress.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

void ExtractOptions::Check() const {
  keyframes.Check();
  sift.Check();
  if (intrinsics) intrinsics->Check();
  LOOPSFM_REQUIRE_OPTION(num_threads >= 0, "--threads must be 0 (all cores) or positive, got {}",
                         num_threads);
}

namespace {

// One camera per image size (per source for video); reuses matching cameras already in the
// database so a resumed run keeps its ids.
class CameraRegistry {
 public:
  CameraRegistry(Database& database, const std::optional<Camera>& intrinsics,
                 CameraModelId guess_model)
      : database_(database), intrinsics_(intrinsics), guess_model_(guess_model) {
    for (const Camera& camera : database_.ReadCameras()) stored_.push_back(camera);
  }

  camera_t CameraFor(int width, int height, const std::string& frame_name) {
    const auto key = std::make_pair(width, height);
    if (auto it = by_size_.find(key); it != by_size_.end()) return it->second;
    Camera camera;
    if (intrinsics_) {
      if (intrinsics_->width != width || intrinsics_->height != height) {
        throw InputError(fmt::format(
            "frame '{}' is {}x{} but the intrinsics file describes a {}x{} camera; pass "
            "intrinsics for this size, or drop --intrinsics to let loopsfm guess",
            frame_name, width, height, intrinsics_->width, intrinsics_->height));
      }
      camera = *intrinsics_;
    } else {
      camera = Camera::GuessFromImageSize(width, height, guess_model_);
    }
    camera_t id = kInvalidCameraId;
    for (const Camera& stored : stored_) {
      if (stored.SameIntrinsics(camera) &&
          stored.has_prior_focal_length == camera.has_prior_focal_length) {
        id = stored.camera_id;
        break;
      }
    }
    if (id == kInvalidCameraId) {
      id = database_.WriteCamera(camera);
      if (!by_size_.empty()) {
        spdlog::warn("frame '{}' is {}x{}, a new size: it gets camera {} of its own", frame_name,
                     width, height, id);
      }
    }
    by_size_[key] = id;
    return id;
  }


 private:
  Database& database_;
  std::optional<Camera> intrinsics_;
  CameraModelId guess_model_;
  std::vector<Camera> stored_;
  std::map<std::pair<int, int>, camera_t> by_size_;
};

struct WorkItem {
  // The keyframe without its pixels: only the SIFT input travels through the pipeline, so a
  // large frame is held no longer than it takes to decode and shrink it.
  Keyframe keyframe;
  int width = 0, height = 0;
  bool resumed = false;
  SiftInput sift_input;
  FeatureSet features;
};

// Writes one frame with its camera, features and origin, in one transaction.
void StoreFrame(const Keyframe& keyframe, int width, int height, const FeatureSet& features,
                CameraRegistry& cameras, Database& database) {
  const RawFrame& raw = keyframe.frame;
  Frame frame;
  frame.name = raw.name;
  frame.camera_id = cameras.CameraFor(width, height, raw.name);
  Database::Transaction transaction(database);
  frame.image_id = database.WriteFrame(frame);
  database.WriteFeatures(frame.image_id, features);
  database.WriteFrameOrigin(frame.image_id, {raw.source_index, keyframe.sharpness,
                                             std::string(KeyframeReasonName(keyframe.reason))});
  transaction.Commit();
}

void PutSiftRequest(ByteWriter& request, const SiftInput& input, const SiftOptions& options) {
  request.Put(options);
  request.Put(input.scale_x);
  request.Put(input.scale_y);
  PutGreyImage(request, input.grey);
}

}  // namespace

WorkHandler SiftWorkHandler() {
  return [](ByteReader& request) {
    const auto options = request.Get<SiftOptions>();
    SiftInput input;
    input.scale_x = request.Get<double>();
    input.scale_y = request.Get<double>();
    input.grey = GetGreyImage(request);
    return [options, input = std::move(input)](ByteWriter& result) {
      PutFeatures(result, ExtractSift(input, options));
    };
  };
}

ExtractReport ExtractFillInFrames(const std::filesystem::path& input, Database& database,
                                  const ExtractOptions& options,
                                  const std::vector<int>& source_indices) {
  Timer timer;
  ExtractReport report;
  std::set<int> wanted(source_indices.begin(), source_indices.end());
  if (wanted.empty()) return report;
  CameraRegistry cameras(database, options.intrinsics, options.camera_model);
  std::unique_ptr<FrameSource> source = OpenFrameSource(input);
  std::vector<Keyframe> frames;
  while (!wanted.empty()) {
    std::optional<RawFrame> raw = source->Next();
    if (!raw) break;
    if (!wanted.erase(raw->source_index)) continue;
    const double sharpness = FrameSharpness(raw->image);
    frames.push_back(Keyframe{std::move(*raw), sharpness, KeyframeReason::kFillIn});
  }
  if (!wanted.empty()) {
    throw InputError(fmt::format("frame {} of '{}' could not be read again for a fill-in; the "
                                 "source changed since extraction: start again with --overwrite",
                                 *wanted.begin(), input.string()));
  }
  std::vector<FeatureSet> features(frames.size());
  tbb::parallel_for(size_t(0), frames.size(), [&](size_t i) {
    features[i] = ExtractSift(PrepareSiftInput(frames[i].frame.image, options.sift), options.sift);
  });
  for (size_t i = 0; i < frames.size(); ++i) {
    const cv::Mat& image = frames[i].frame.image;
    StoreFrame(frames[i], image.cols, image.rows, features[i], cameras, database);
    ++report.frames_extracted;
    report.num_features += features[i].Size();
  }
  report.frames_decoded = static_cast<int>(frames.size());
  report.seconds = timer.ElapsedSeconds();
  return report;
}

ExtractReport ExtractFeatures(const std::filesystem::path& input, Database& database,
                              const ExtractOptions& options) {
  options.Check();
  Timer timer;
  std::unique_ptr<FrameSource> source = OpenFrameSource(input);
  KeyframeOptions keyframe_options = options.keyframes;
  if (options.intrinsics && keyframe_options.adaptive.focal_length_px == 0.0) {
    keyframe_options.adaptive.focal_length_px = options.intrinsics->MeanFocalLength();
  }
  KeyframeSelector selector(*source, keyframe_options);
  CameraRegistry cameras(database, options.intrinsics, options.camera_model);

  // Parallelism is across frames; OpenCV's own threads inside one frame would oversubscribe.
  const int previous_cv_threads = cv::getNumThreads();
  cv::setNumThreads(1);

  // Stored features from another source or other options must not be mixed with new ones.
  CheckFingerprint(database, "extract", ExtractFingerprint(input, options));
  // Later stages pick defaults by the kind of input (e.g. loop detection for video).
  database.WriteMeta("source_kind", source->Info().kind == SourceKind::kVideo ? "video" : "images");
  // Where the frames come from, for exports that need their pixels again (`loopsfm export`).
  database.WriteMeta("source_path", std::filesystem::absolute(input).lexically_normal().string());
  const KeyframeMode mode = ResolvedKeyframeMode(options.keyframes, source->Info().kind);
  // Adaptive selection keeps an unknown number of frames: the bar shows a count only.
  const int expected = mode == KeyframeMode::kAdaptive
                           ? 0
                           : source->Info().expected_frames / options.keyframes.every;
  Progress progress("extract", expected > 0 ? expected : 0, options.show_progress, options.hooks);
  ExtractReport report;
  // Names of frames stored with features by an earlier run.
  std::unordered_set<std::string> already_extracted;
  for (const Frame& frame : database.ReadFrames()) {
    if (database.HasFeatures(frame.image_id)) already_extracted.insert(frame.name);
  }
  std::optional<WorkSharing> own_sharing;
  WorkSharing& sharing = options.sharing ? *options.sharing
                                         : own_sharing.emplace(nullptr, options.num_threads);
  // Frames being extracted, by unit. Units are added and removed on this thread and looked
  // up from the computing threads: the lock guards the map, not the items.
  std::map<size_t, std::unique_ptr<WorkItem>> open;
  std::mutex open_mutex;
  auto item_of = [&](size_t i) -> WorkItem& {
    std::lock_guard<std::mutex> lock(open_mutex);
    return *open.at(i);
  };
  WorkSharing::Job job;
  job.kind = WorkKind::kExtractSift;
  job.next = [&](size_t i) {
    // Decoding and keyframe selection run here, in frame order.
    Timer decode_timer;
    std::optional<Keyframe> keyframe = selector.Next();
    if (!keyframe) {
      report.decode_seconds += decode_timer.ElapsedSeconds();
      return false;
    }
    auto item = std::make_unique<WorkItem>();
    item->keyframe = std::move(*keyframe);
    cv::Mat& image = item->keyframe.frame.image;
    item->width = image.cols;
    item->height = image.rows;
    item->resumed = already_extracted.count(item->keyframe.frame.name) > 0;
    if (!item->resumed) item->sift_input = PrepareSiftInput(image, options.sift);
    image.release();
    report.decode_seconds += decode_timer.ElapsedSeconds();
    std::lock_guard<std::mutex> lock(open_mutex);
    open.emplace(i, std::move(item));
    return true;
  };
  job.has_work = [&](size_t i) { return !item_of(i).resumed; };
  job.compute = [&](size_t i) {
    WorkItem& item = item_of(i);
    item.features = ExtractSift(item.sift_input, options.sift);
    item.sift_input = SiftInput();
  };
  job.request = [&](size_t i, int, ByteWriter& request) {
    WorkItem& item = item_of(i);
    PutSiftRequest(request, item.sift_input, options.sift);
    item.sift_input = SiftInput();
  };
  job.take_result = [&](size_t i, int, ByteReader& result) {
    item_of(i).features = GetFeatures(result);
  };
  job.finish = [&](size_t i) {
    std::unique_ptr<WorkItem> item;
    {
      std::lock_guard<std::mutex> lock(open_mutex);
      item = std::move(open.at(i));
      open.erase(i);
    }
    ++report.frames_decoded;
    progress.Advance();
    if (item->resumed) {
      ++report.frames_resumed;
      return;
    }
    StoreFrame(item->keyframe, item->width, item->height, item->features, cameras, database);
    ++report.frames_extracted;
    report.num_features += item->features.Size();
  };
  try {
    sharing.Run(job);
  } catch (...) {
    cv::setNumThreads(previous_cv_threads);
    throw;
  }
  cv::setNumThreads(previous_cv_threads);
  report.frames_per_rank = sharing.UnitsPerRank();
  progress.Finish();
  report.frames_read = mode == KeyframeMode::kAdaptive ? selector.Summary().frames_read
                                                       : report.frames_decoded;
  if (mode == KeyframeMode::kAdaptive) {
    // What the report draws along the video: how many frames there were, which were blurred.
    const KeyframeSummary& summary = selector.Summary();
    database.WriteMeta("keyframes", nlohmann::json{{"mode", "adaptive"},
                                                   {"frames_read", summary.frames_read},
                                                   {"blurred", summary.blurred}}
                                        .dump());
    report.frames_blurred = static_cast<int>(summary.blurred.size());
  }
  report.unreadable_images = source->NumSkipped();
  report.num_cameras = static_cast<int>(database.NumCameras());
  report.seconds = timer.ElapsedSeconds();
  return report;
}

nlohmann::json ToJson(const ExtractReport& r) {
  return {{"frames_read", r.frames_read},
          {"frames_blurred", r.frames_blurred},
          {"frames_decoded", r.frames_decoded},
          {"frames_extracted", r.frames_extracted},
          {"frames_resumed", r.frames_resumed},
          {"unreadable_images", r.unreadable_images},
          {"num_cameras", r.num_cameras},
          {"num_features", r.num_features},
          {"seconds", r.seconds},
          {"decode_seconds", r.decode_seconds},
          {"frames_per_rank", r.frames_per_rank}};
}

}  // namespace loopsfm
