#pragma once
// The data of OUT/report.html for a finished run (schema in report/html_report.h): the
// summary, time per stage and peak memory, cameras, every frame along the video with its
// registration and points, which frames of the source were kept as keyframes and why
// (timeline {frames_read, kept [[index, reason], ...], blurred [...], localized [...]},
// source indices, when frames were read), the points and frusta of model 0, the similarity
// and match matrices, the loops closed, a top view of the path (before and after loop
// closing where loops were closed; aligned to the ground truth, with the errors, when it is
// given).

#include <filesystem>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>

#include "loopsfm/pipeline/reconstruct.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/scene/frame.h"

namespace loopsfm {

nlohmann::json RunReportData(const ReconstructReport& report,
                             const std::vector<Reconstruction>& models,
                             const std::vector<Frame>& frames, const std::filesystem::path& input,
                             const std::filesystem::path& output_dir,
                             const std::optional<std::vector<TrajectoryEntry>>& groundtruth);

}  // namespace loopsfm
