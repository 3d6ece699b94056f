#pragma once
// The HTML report: one self-contained file that opens offline from file:// (no server, no
// network). It holds the report's data as JSON, the stylesheet and the bundled front-end
// script (three.js 3D view of points and camera frusta, Chart.js plots; sources in web/),
// which renders the data in the browser.
//
//   nlohmann::json data = {{"title", "loopsfm: block.mp4"}, {"summary", {{"frames", 440}}}};
//   WriteHtmlReport(out / "report.html", data);
//
// The data (every field optional; a section without data is left out):
//   title, input, output, created                      strings
//   summary     {frames, registered, models, mapper, points, mean_track_length,
//                reprojection_error_px, total_seconds, peak_memory_mib, warnings [text]}
//   stages      [{name, seconds}]                      time per stage (bar chart)
//   cameras     [{camera_id, model, width, height, params, focal_px, cx, cy}]
//   frames      [{index, name, registered, model, camera_id, num_points2D, num_points3D,
//                 center [x, y, z], world_from_cam_rotation [r00 r01 r02 r10 ... r22]}]
//               in capture order; center and rotation (row-major, OpenCV camera axes: x
//               right, y down, z forward) only for registered frames. The 3D view draws
//               the frames of model 0 as frusta; the per-frame chart shows all.
//   timeline    {frames_read, kept [[source_index, reason], ...], blurred [index, ...],
//                localized [index, ...]}  every frame of the source along the video: kept
//               (by KeyframeReasonName), localised between keyframes, blurred, skipped
//   points      {xyz [x0 y0 z0 x1 ...], rgb [r0 g0 b0 ...]}  points of model 0, rgb 0..255
//   matrices    [{title, png_base64}]                  similarity / match matrix images
//   top_view    {x_label, y_label, paths [{label, xy [[x, y], ...]}]}  2D, one scale; a
//               path whose label holds "ground truth" is drawn grey
//   loops       [{recent_frame, old_frame, num_inliers, num_correspondences,
//                 correction_translation, correction_rotation_deg, correction_scale, seconds}]
//   evaluation  {ate_fraction_of_path, ate_rmse, rotation_error_mean_deg, loop_gap_max,
//                loop_gap_mean}

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

namespace loopsfm {

// The whole HTML document for `data`. Every '<' in the JSON is written as \u003c, so no
// string in the data can end the script tag that holds it; invalid UTF-8 in strings is
// replaced by U+FFFD.
std::string HtmlReport(const nlohmann::json& data);

// Writes HtmlReport(data) to `file` (its folder must exist). Throws StorageError naming the
// file when it cannot be written.
void WriteHtmlReport(const std::filesystem::path& file, const nlohmann::json& data);

}  // namespace loopsfm
