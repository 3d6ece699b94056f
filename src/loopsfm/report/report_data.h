#pragma once
// Parts of the HTML report's data (the schema is in html_report.h) built from the run's
// models, so every writer of a report fills them the same way.
//
//   nlohmann::json data;
//   data["cameras"] = ReportCameras(models[0]);
//   data["frames"] = ReportFrames(database.ReadFrames(), models);
//   data["points"] = ReportPoints(models[0]);
//   data["matrices"].push_back(ReportImage("Verified matches", out / "database_matches.png"));

#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "loopsfm/report/top_view.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/scene/frame.h"
#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

// The cameras of a model in id order: camera_id, model, width, height, params, focal_px
// (mean focal length), cx, cy.
nlohmann::json ReportCameras(const Reconstruction& model);

// One entry per frame, in the order given (capture order): index (position in `frames`),
// name, registered, and for a frame registered in models[k]: model k, camera_id,
// num_points2D, num_points3D, center and world_from_cam_rotation (row-major).
nlohmann::json ReportFrames(const std::vector<Frame>& frames, const std::vector<Reconstruction>& models);

// {xyz, rgb} of at most max_points points of the model, every n-th in id order.
nlohmann::json ReportPoints(const Reconstruction& model, size_t max_points = 200000);

// {label, xy} of a path seen from above: its centres projected onto `plane`.
nlohmann::json ReportTopViewPath(const std::string& label, const std::vector<Eigen::Vector3d>& centres,
                                 const TopViewPlane& plane);

// Loop links (OUT/loop_links.txt) as segments of the top view, one entry per method, in the
// order the methods first appear: {"label": "loop links (METHOD): N", "method": METHOD,
// "segments": [[x1, y1, x2, y2], ...]}. `centres` maps frame names to the centres the view
// draws; a link with a frame not among them is left out.
nlohmann::json ReportTopViewLinks(const std::vector<LoopLink>& links,
                                  const std::map<std::string, Eigen::Vector3d>& centres,
                                  const TopViewPlane& plane);

// {title, png_base64} of an image file (a matrix plot). Throws InputError naming the file
// when it cannot be read.
nlohmann::json ReportImage(const std::string& title, const std::filesystem::path& png);

// Standard base64 (RFC 4648, with padding).
std::string Base64Encode(std::string_view bytes);

}  // namespace loopsfm
