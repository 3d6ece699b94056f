#include "loopsfm/pipeline/export.h"

#include <algorithm>
#include <map>
#include <optional>
#include <set>
#include <unordered_map>

#include <opencv2/imgcodecs.hpp>

#include "loopsfm/eval/trajectory_metrics.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/storage/nerfstudio.h"
#include "loopsfm/storage/ply.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"
#include "loopsfm/video/frame_source.h"

namespace loopsfm {
namespace fs = std::filesystem;
namespace {

image_t MaxImageId(const Reconstruction& model) {
  return model.Images().empty() ? 0 : model.Images().rbegin()->first;
}

constexpr std::pair<ExportFormat, std::string_view> kFormatNames[] = {
    {ExportFormat::kColmap, "colmap"},         {ExportFormat::kPly, "ply"},
    {ExportFormat::kTum, "tum"},               {ExportFormat::kImages, "images"},
    {ExportFormat::kNerfstudio, "nerfstudio"}, {ExportFormat::kGsplat, "gsplat"},
    {ExportFormat::kReport, "report"},
};

// A folder written beside the one it replaces ("<name>.new") and swapped in by Commit().
class ReplacementFolder {
 public:
  explicit ReplacementFolder(fs::path final_path)
      : final_(std::move(final_path)), staging_(final_.string() + ".new") {
    fs::remove_all(staging_);
    CreateFolder(staging_);
  }
  const fs::path& path() const { return staging_; }
  void Commit() {
    fs::remove_all(final_);
    fs::rename(staging_, final_);
  }

 private:
  fs::path final_, staging_;
};

void WriteImage(const fs::path& path, const cv::Mat& image) {
  std::vector<int> params;
  const std::string ext = path.extension().string();
  if (ext == ".png") params = {cv::IMWRITE_PNG_COMPRESSION, 1};
  if (ext == ".jpg" || ext == ".jpeg") params = {cv::IMWRITE_JPEG_QUALITY, 95};
  if (!cv::imwrite(path.string(), image, params)) {
    throw StorageError(fmt::format("cannot write '{}': check the disk space and that the folder "
                                   "is writable",
                                   path.string()));
  }
}

ModelSummary Summarize(const Reconstruction& model, fs::path path) {
  ModelSummary summary;
  summary.path = std::move(path);
  summary.num_registered = model.NumRegImages();
  summary.num_points = model.NumPoints3D();
  for (const auto& [id, camera] : model.Cameras()) summary.cameras.push_back(camera);
  std::sort(summary.cameras.begin(), summary.cameras.end(),
            [](const Camera& a, const Camera& b) { return a.camera_id < b.camera_id; });
  summary.mean_track_length = model.ComputeMeanTrackLength();
  Reconstruction copy = model;
  summary.mean_reprojection_error = copy.UpdateReprojectionErrors();
  return summary;
}

// Point colours: the mean of the pixels that observe each point, summed frame by frame.
class Colorizer {
 public:
  explicit Colorizer(std::vector<Reconstruction>* models)
      : models_(models), sums_(models->size()), counts_(models->size()) {
    for (size_t m = 0; m < models->size(); ++m) {
      for (image_t id : (*models)[m].RegImageIds()) by_name_[(*models)[m].GetImage(id).name].push_back({m, id});
    }
  }
  void Add(const RawFrame& frame) {
    const auto it = by_name_.find(frame.name);
    if (it == by_name_.end()) return;
    for (const auto& [m, image_id] : it->second) {
      for (const Point2D& p : (*models_)[m].GetImage(image_id).points2D) {
        if (!p.HasPoint3D()) continue;
        const int col = std::clamp(static_cast<int>(p.xy.x()), 0, frame.image.cols - 1);
        const int row = std::clamp(static_cast<int>(p.xy.y()), 0, frame.image.rows - 1);
        const cv::Vec3b bgr = frame.image.at<cv::Vec3b>(row, col);
        // try_emplace: a default-constructed Eigen vector is uninitialised, not zero.
        sums_[m].try_emplace(p.point3D_id, Eigen::Vector3d::Zero()).first->second +=
            Eigen::Vector3d(bgr[2], bgr[1], bgr[0]);
        ++counts_[m][p.point3D_id];
      }
    }
  }
  void Apply() {
    for (size_t m = 0; m < models_->size(); ++m) {
      for (auto& [id, point] : (*models_)[m].Points3D()) {
        const auto c = counts_[m].find(id);
        if (c == counts_[m].end()) continue;
        point.color = (sums_[m][id] / c->second).array().round().cast<uint8_t>();
      }
    }
  }

 private:
  std::vector<Reconstruction>* models_;
  std::unordered_map<std::string, std::vector<std::pair<size_t, image_t>>> by_name_;
  std::vector<std::unordered_map<point3D_t, Eigen::Vector3d>> sums_;
  std::vector<std::unordered_map<point3D_t, int>> counts_;
};

// Model 0's registered frames, undistorted to PINHOLE as they stream by.
class GsplatWriter {
 public:
  GsplatWriter(const Reconstruction& model, const fs::path& images_dir,
               const UndistortOptions& options)
      : model_(model), images_dir_(images_dir) {
    for (image_t id : model.RegImageIds()) by_name_[model.GetImage(id).name] = id;
    for (const auto& [id, camera] : model.Cameras()) {
      undistorters_.try_emplace(id, camera, options);
    }
  }
  size_t Add(const RawFrame& frame) {
    const auto it = by_name_.find(frame.name);
    if (it == by_name_.end()) return 0;
    const ImageUndistorter& undistorter = undistorters_.at(model_.GetImage(it->second).camera_id);
    WriteImage(images_dir_ / frame.name, undistorter.Undistort(frame.image));
    return 1;
  }
  Reconstruction UndistortedModel() const {
    std::map<camera_t, Camera> cameras;
    for (const auto& [id, undistorter] : undistorters_) cameras[id] = undistorter.undistorted();
    return UndistortReconstruction(model_, cameras);
  }

 private:
  const Reconstruction& model_;
  fs::path images_dir_;
  std::unordered_map<std::string, image_t> by_name_;
  std::map<camera_t, ImageUndistorter> undistorters_;
};

bool SameFolder(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  return fs::exists(a) && fs::exists(b) && fs::equivalent(a, b, ec);
}

}  // namespace

void CreateFolder(const fs::path& dir, std::string_view what) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) {
    throw StorageError(fmt::format("cannot create {}'{}': {}", what, dir.string(),
                                   ec ? ec.message() : "a file of that name exists"));
  }
}

std::string_view ExportFormatName(ExportFormat format) {
  for (const auto& [f, name] : kFormatNames) {
    if (f == format) return name;
  }
  return "?";
}

std::set<ExportFormat> DefaultExportFormats() {
  std::set<ExportFormat> formats;
  for (const auto& [f, name] : kFormatNames) {
    if (f != ExportFormat::kGsplat) formats.insert(f);
  }
  return formats;
}

std::set<ExportFormat> ParseExportFormats(const std::string& list) {
  if (list == "default") return DefaultExportFormats();
  std::set<ExportFormat> formats;
  if (list == "none") return formats;
  if (list == "all") {
    for (const auto& [f, name] : kFormatNames) formats.insert(f);
    return formats;
  }
  std::string known;
  for (const auto& [f, name] : kFormatNames) known += (known.empty() ? "" : ", ") + std::string(name);
  size_t start = 0;
  while (start <= list.size()) {
    const size_t end = std::min(list.find(',', start), list.size());
    const std::string entry = list.substr(start, end - start);
    bool found = false;
    for (const auto& [f, name] : kFormatNames) {
      if (entry == name) {
        formats.insert(f);
        found = true;
      }
    }
    if (!found) {
      throw InvalidArgument(fmt::format("unknown export format '{}' (in '{}'); list any of {}, "
                                        "or all, default, none",
                                        entry, list, known));
    }
    start = end + 1;
  }
  return formats;
}

void ExportOptions::Check() const { undistort.Check(); }

ExportReport Export(std::vector<Reconstruction>* models,
                    const std::vector<std::string>& kept_frames, const fs::path& frames_source, const fs::path& output_dir,
                    const ExportOptions& options, const std::vector<LocalizedFrame>& localized) {
  options.Check();
  Timer timer;
  ExportReport report;
  if (models->empty()) return report;
  auto wants = [&](ExportFormat f) { return options.formats.count(f) > 0; };
  // Model 0 with its localised frames as registered images without observations: what the
  // trajectory and transforms.json show (and the COLMAP model, when asked).
  std::optional<Reconstruction> model0_all;
  std::vector<std::string> frames = kept_frames;
  // A model written with --localized-in-model holds them already (`loopsfm export` again).
  std::set<std::string> in_model0;
  for (const auto& [id, image] : (*models)[0].Images()) in_model0.insert(image.name);
  for (const LocalizedFrame& frame : localized) {
    if (frame.pose.model != 0) continue;
    frames.push_back(frame.name);
    if (in_model0.count(frame.name)) continue;
    if (!model0_all) model0_all = (*models)[0];
    Image image;
    const image_t image_id = MaxImageId(*model0_all) + 1;
    image.image_id = image_id;
    image.camera_id = frame.pose.camera_id;
    image.name = frame.name;
    image.cam_from_world = frame.pose.cam_from_world;
    model0_all->AddImage(std::move(image));
    model0_all->RegisterImage(image_id);
  }
  const Reconstruction& model0 = (*models)[0];
  const Reconstruction& path0 = model0_all ? *model0_all : model0;
  const Reconstruction& written0 = options.localized_in_model ? path0 : model0;
  // Formats that cannot be written fail before anything is.
  std::optional<nlohmann::json> transforms;
  if (wants(ExportFormat::kNerfstudio)) {
    NerfstudioOptions ns;
    if (!wants(ExportFormat::kPly) && !fs::exists(output_dir / "points.ply")) ns.ply_file_path = "";
    transforms = NerfstudioTransforms(path0, ns);
  }

  // One pass over the frames for images, gsplat and colours.
  const fs::path images_dir = output_dir / "images";
  const bool write_images =
      wants(ExportFormat::kImages) && !SameFolder(frames_source, images_dir);
  const bool write_gsplat = wants(ExportFormat::kGsplat);
  if (write_images || write_gsplat || options.colorize) {
    std::unique_ptr<FrameSource> source = OpenFrameSource(frames_source);
    const bool copy_files = source->Info().kind == SourceKind::kImageFolder;
    std::optional<ReplacementFolder> images, undistorted;
    if (write_images) images.emplace(images_dir);
    std::optional<GsplatWriter> gsplat;
    if (write_gsplat) {
      undistorted.emplace(output_dir / "undistorted");
      CreateFolder(undistorted->path() / "images");
      gsplat.emplace(written0, undistorted->path() / "images", options.undistort);
    }
    Colorizer colorizer(models);
    std::unordered_map<std::string, bool> seen;
    for (const std::string& name : frames) seen[name] = false;
    size_t found = 0;
    while (found < seen.size()) {
      std::optional<RawFrame> frame = source->Next();
      if (!frame) break;
      auto it = seen.find(frame->name);
      if (it == seen.end() || it->second) continue;
      it->second = true;
      ++found;
      if (options.colorize) colorizer.Add(*frame);
      if (images) {
        if (copy_files) {
          fs::copy_file(source->Info().path / frame->name, images->path() / frame->name,
                        fs::copy_options::overwrite_existing);
        } else {
          WriteImage(images->path() / frame->name, frame->image);
        }
        ++report.num_images_written;
      }
      if (gsplat) report.num_undistorted_written += gsplat->Add(*frame);
    }
    if (found < seen.size()) {
      for (const auto& [name, was_seen] : seen) {
        if (was_seen) continue;
        throw InputError(fmt::format("frame '{}' is not in '{}' ({} of {} frames found): the "
                                     "source is not the one this run was made from; pass the "
                                     "original video or folder",
                                     name, frames_source.string(), found, seen.size()));
      }
    }
    if (options.colorize) colorizer.Apply();
    if (images) {
      images->Commit();
      report.written.push_back(images_dir);
    }
    if (gsplat) {
      const fs::path sparse = undistorted->path() / "sparse" / "0";
      CreateFolder(sparse);
      WriteColmapModelBinary(sparse, gsplat->UndistortedModel());
      undistorted->Commit();
      report.written.push_back(output_dir / "undistorted");
    }
  }

  if (wants(ExportFormat::kColmap)) {
    ReplacementFolder sparse(output_dir / "sparse");
    for (size_t m = 0; m < models->size(); ++m) {
      const fs::path dir = sparse.path() / std::to_string(m);
      CreateFolder(dir);
      const Reconstruction& model = m == 0 ? written0 : (*models)[m];
      WriteColmapModelBinary(dir, model);
      if (options.write_text) WriteColmapModelText(dir, model);
    }
    sparse.Commit();
    report.written.push_back(output_dir / "sparse");
  }
  for (size_t m = 0; m < models->size(); ++m) {
    report.models.push_back(Summarize((*models)[m], output_dir / "sparse" / std::to_string(m)));
  }
  if (wants(ExportFormat::kPly)) {
    WritePly(output_dir / "points.ply", model0);
    report.written.push_back(output_dir / "points.ply");
  }
  if (wants(ExportFormat::kTum)) {
    WriteTrajectoryFile(output_dir / "trajectory.txt", TrajectoryFromReconstruction(path0));
    report.written.push_back(output_dir / "trajectory.txt");
  }
  if (transforms) {
    if (!fs::is_directory(images_dir)) {
      spdlog::warn("transforms.json points at images/, which is not there; export the frames "
                   "too (--export ...,images)");
    }
    WriteNerfstudioTransforms(output_dir / "transforms.json", *transforms);
    report.written.push_back(output_dir / "transforms.json");
  }
  report.seconds = timer.ElapsedSeconds();
  return report;
}

ExportReport ExportRun(const fs::path& output_dir, const std::optional<fs::path>& frames_source,
                       const ExportOptions& options) {
  if (options.formats.count(ExportFormat::kReport)) {
    throw InvalidArgument("report.html is written by `loopsfm reconstruct` (it shows the run's "
                          "timings): run it again with --export ...,report (finished stages are "
                          "reused)");
  }
  std::vector<Reconstruction> models;
  for (int m = 0; fs::is_directory(output_dir / "sparse" / std::to_string(m)); ++m) {
    models.push_back(ReadColmapModel(output_dir / "sparse" / std::to_string(m)));
  }
  if (models.empty()) {
    throw InputError(fmt::format("'{}' holds no model (sparse/0): run `loopsfm reconstruct INPUT "
                                 "-o {}` first",
                                 output_dir.string(), output_dir.string()));
  }
  // Kept frames in capture order from the database; without one, the models' frames.
  std::vector<std::string> frames;
  std::optional<fs::path> recorded_source;
  if (fs::exists(output_dir / "database.db")) {
    const Database database = Database::Open((output_dir / "database.db").string());
    for (const Frame& frame : FramesInCaptureOrder(database)) frames.push_back(frame.name);
    if (auto path = database.ReadMeta("source_path")) recorded_source = *path;
  } else {
    std::set<std::string> names;
    for (const Reconstruction& model : models) {
      for (const auto& [id, image] : model.Images()) names.insert(image.name);
    }
    frames.assign(names.begin(), names.end());
  }
  ExportOptions run_options = options;
  run_options.colorize = false;  // the models carry their colours
  const bool needs_frames = options.formats.count(ExportFormat::kImages) > 0 ||
                            options.formats.count(ExportFormat::kGsplat) > 0;
  fs::path source;
  if (frames_source) {
    source = *frames_source;
  } else if (fs::is_directory(output_dir / "images") &&
             std::all_of(frames.begin(), frames.end(), [&](const std::string& name) {
               return fs::exists(output_dir / "images" / name);
             })) {
    source = output_dir / "images";
  } else if (recorded_source && fs::exists(*recorded_source)) {
    source = *recorded_source;
  } else if (needs_frames) {
    throw InputError(fmt::format(
        "the frames of '{}' are needed for images/gsplat, but neither {}/images nor the "
        "recorded source ('{}') holds them: pass the video or folder with --input",
        output_dir.string(), output_dir.string(), recorded_source.value_or("none").string()));
  }
  if (!needs_frames) source.clear();
  // The frames localised between keyframes (--all-frames), in model 0's camera.
  std::vector<LocalizedFrame> localized;
  if (fs::exists(output_dir / "localized.txt")) {
    if (models[0].Cameras().size() != 1) {
      spdlog::warn("{}/localized.txt is left out: model 0 has {} cameras, and the file does not "
                   "say which one each frame used",
                   output_dir.string(), models[0].Cameras().size());
    } else {
      const camera_t camera_id = models[0].Cameras().begin()->first;
      for (const TrajectoryEntry& entry : ReadTrajectoryFile(output_dir / "localized.txt")) {
        LocalizedFrame frame;
        frame.name = entry.name;
        frame.pose.camera_id = camera_id;
        frame.pose.cam_from_world = entry.world_from_cam.Inverse();
        localized.push_back(std::move(frame));
      }
    }
  }
  return Export(&models, frames, source, output_dir, run_options, localized);
}

std::string ExportReport::Counts() const {
  std::string counts;
  if (num_images_written > 0) counts += fmt::format("{} frames, ", num_images_written);
  if (num_undistorted_written > 0) counts += fmt::format("{} undistorted, ", num_undistorted_written);
  return counts + fmt::format("{:.1f} s", seconds);
}

}  // namespace loopsfm
