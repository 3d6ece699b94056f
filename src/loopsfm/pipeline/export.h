#pragma once
// What a run leaves for other tools, written from the models (largest first) and the frames:
//   colmap      OUT/sparse/<k>/{cameras,images,points3D}.bin (+ .txt with write_text)
//   ply         OUT/points.ply: coloured points of model 0
//   tum         OUT/trajectory.txt: camera-to-world poses of model 0 (and of the frames
//               localised in it), by frame name
//   images      OUT/images/<name>: every kept frame, named as in the models (a video's frames
//               as PNG; an image folder's files copied as they are)
//   nerfstudio  OUT/transforms.json for model 0, pointing at images/ and points.ply
//   gsplat      OUT/undistorted/{images,sparse/0}: model 0 undistorted to PINHOLE, the layout
//               the Gaussian-splatting convert.py leaves (COLMAP's image_undistorter)
//   report      OUT/report.html: written by Reconstruct (run_report.h), which holds the run's
//               timings; Export itself skips it
// Folders that are replaced (sparse/, images/, undistorted/) are written beside the old ones
// and swapped in when complete, so an interrupted export never leaves a mix or loses the old.

#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "loopsfm/pipeline/localize.h"
#include "loopsfm/pipeline/undistort.h"
#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

enum class ExportFormat { kColmap, kPly, kTum, kImages, kNerfstudio, kGsplat, kReport };

// Creates `dir` and its parents; StorageError "cannot create WHAT'DIR': why" when it cannot
// (`what`: e.g. "output folder ", or empty).
void CreateFolder(const std::filesystem::path& dir, std::string_view what = "");

std::string_view ExportFormatName(ExportFormat format);
// Every format but gsplat (which writes every registered frame a second time).
std::set<ExportFormat> DefaultExportFormats();
// "colmap,ply,images", "all", "default", or "none". Throws InvalidArgument naming the
// unknown entries and the known formats.
std::set<ExportFormat> ParseExportFormats(const std::string& list);

struct ExportOptions {
  std::set<ExportFormat> formats = DefaultExportFormats();
  // Also write the COLMAP models as text.
  bool write_text = false;
  UndistortOptions undistort;
  // Read the frames again to give the 3D points the mean colour of their observations.
  bool colorize = true;
  // Localised frames (--all-frames) also go into the COLMAP model 0 and the undistorted
  // layout, as registered images without observations; otherwise only into the
  // trajectory, transforms.json and images/.
  bool localized_in_model = false;
  void Check() const;
};

struct ModelSummary {
  std::filesystem::path path;
  size_t num_registered = 0;
  size_t num_points = 0;
  double mean_track_length = 0.0;
  double mean_reprojection_error = 0.0;
  // The model's cameras, as refined.
  std::vector<Camera> cameras;
};

struct ExportReport {
  std::vector<ModelSummary> models;
  // What was written (files and folders under the output folder), in writing order.
  std::vector<std::filesystem::path> written;
  size_t num_images_written = 0;
  size_t num_undistorted_written = 0;
  double seconds = 0.0;
  // "N frames, M undistorted, S s", naming only the images that were written.
  std::string Counts() const;
};

// Writes the formats asked for. `frames` are the kept frames' names in capture order;
// `frames_source` is the video or image folder they come from (read once, and only when
// images, gsplat or colours need pixels). With no model, nothing earlier is touched.
// Throws InvalidArgument for a format the models cannot be written in, StorageError when
// the output cannot be written, InputError when the source lacks a frame.
// `localized` are the frames localised between keyframes (pipeline/localize.h); those of
// model 0 join its trajectory, transforms.json and images/ (and the model itself when
// options.localized_in_model).
ExportReport Export(std::vector<Reconstruction>* models, const std::vector<std::string>& frames,
                    const std::filesystem::path& frames_source,
                    const std::filesystem::path& output_dir, const ExportOptions& options,
                    const std::vector<LocalizedFrame>& localized = {});

// Exports an earlier run again from what OUT holds (OUT/sparse/<k>, OUT/database.db), without
// recomputing anything, with the localised frames of OUT/localized.txt when it is there.
// Frames are read from `frames_source` when given, else from OUT/images
// when it holds them, else from the video or folder the run was made from. Throws InputError
// when OUT holds no model, or a format needs frames and none of these has them, and
// InvalidArgument for the report (it needs the run itself).
ExportReport ExportRun(const std::filesystem::path& output_dir,
                       const std::optional<std::filesystem::path>& frames_source,
                       const ExportOptions& options);

}  // namespace loopsfm
