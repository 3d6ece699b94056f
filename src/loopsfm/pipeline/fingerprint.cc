#include "loopsfm/pipeline/fingerprint.h"

#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/video/frame_source.h"

namespace loopsfm {
namespace fs = std::filesystem;
namespace {

// A file by its name and size; a folder by its name, image count and total size.
nlohmann::json SourceIdentity(const fs::path& input) {
  const fs::path path = fs::absolute(input).lexically_normal();
  const std::string name = (path.has_filename() ? path : path.parent_path()).filename().string();
  if (!fs::is_directory(path)) return {{"name", name}, {"bytes", fs::file_size(path)}};
  uintmax_t bytes = 0;
  int images = 0;
  for (const auto& entry : fs::directory_iterator(path)) {
    if (!entry.is_regular_file() || !HasImageExtension(entry.path())) continue;
    ++images;
    bytes += entry.file_size();
  }
  return {{"name", name}, {"images", images}, {"bytes", bytes}};
}

// "key.sub: stored -> new" for every leaf that differs.
void Differences(const nlohmann::json& stored, const nlohmann::json& now, const std::string& prefix,
                 std::vector<std::string>* out) {
  if (stored.is_object() && now.is_object()) {
    for (const auto& [key, value] : now.items()) {
      const std::string name = prefix.empty() ? key : prefix + "." + key;
      Differences(stored.contains(key) ? stored[key] : nlohmann::json(), value, name, out);
    }
    for (const auto& [key, value] : stored.items()) {
      if (!now.contains(key)) out->push_back(fmt::format("{}.{}: {} -> (none)", prefix, key, value.dump()));
    }
    return;
  }
  if (stored != now) out->push_back(fmt::format("{}: {} -> {}", prefix, stored.dump(), now.dump()));
}

}  // namespace

nlohmann::json ExtractFingerprint(const fs::path& input, const ExtractOptions& options) {
  const SiftOptions& sift = options.sift;
  nlohmann::json intrinsics = nullptr;
  if (options.intrinsics) {
    intrinsics = {{"model", options.intrinsics->ModelName()},
                  {"width", options.intrinsics->width},
                  {"height", options.intrinsics->height},
                  {"params", options.intrinsics->params}};
  }
  nlohmann::json fingerprint = {{"source", SourceIdentity(input)},
          {"every", options.keyframes.every},
          {"sharpest", options.keyframes.sharpest},
          {"sift",
           {{"max_features", sift.max_features},
            {"root_sift", sift.root_sift},
            {"contrast_threshold", sift.contrast_threshold},
            {"edge_threshold", sift.edge_threshold},
            {"num_octave_layers", sift.num_octave_layers},
            {"upscale", sift.upscale},
            {"max_image_size", sift.max_image_size}}},
          {"camera_model", std::string(CameraModelName(options.camera_model))},
          {"intrinsics", intrinsics}};
  // Windows leave the fingerprint as it was before adaptive keyframes, so older databases
  // made with --every resume.
  if (ResolvedKeyframeMode(options.keyframes, OpenFrameSource(input)->Info().kind) ==
      KeyframeMode::kAdaptive) {
    const AdaptiveKeyframeOptions& a = options.keyframes.adaptive;
    fingerprint["keyframes"] = {{"mode", "adaptive"},
                                {"min_parallax_deg", a.min_parallax_deg},
                                {"min_tracked_fraction", a.min_tracked_fraction},
                                {"min_tracked_corners", a.min_tracked_corners},
                                {"max_corners", a.max_corners},
                                {"analysis_size", a.analysis_size},
                                {"blur_fraction", a.blur_fraction},
                                {"lookback_seconds", a.lookback_seconds},
                                {"max_defer_seconds", a.max_defer_seconds},
                                {"focal_length_px", a.focal_length_px}};
  }
  return fingerprint;
}

nlohmann::json MatchFingerprint(const MatchOptions& options) {
  const DescriptorMatchingOptions& m = options.matcher;
  const TwoViewVerificationOptions& v = options.verification;
  return {{"matcher",
           {{"max_ratio", m.max_ratio}, {"max_distance", m.max_distance}, {"cross_check", m.cross_check}}},
          {"verification",
           {{"max_error", v.max_error},
            {"confidence", v.confidence},
            {"max_num_trials", v.max_num_trials},
            {"min_num_inliers", v.min_num_inliers},
            {"min_inlier_ratio", v.min_inlier_ratio},
            {"min_planar_tri_angle_deg", v.min_planar_tri_angle_deg}}}};
}

void CheckFingerprint(Database& database, const std::string& stage,
                      const nlohmann::json& fingerprint) {
  const std::string key = stage + "_fingerprint";
  const std::optional<std::string> stored = database.ReadMeta(key);
  if (!stored) {
    const bool holds_results =
        stage == "match" ? database.NumMatchedPairs() > 0 : database.NumFrames() > 0;
    if (holds_results) {
      spdlog::warn("the database holds {} results from a loopsfm without fingerprints: they are "
                   "taken as made with these options (use --overwrite if they were not)",
                   stage);
    }
    database.WriteMeta(key, fingerprint.dump());
    return;
  }
  const nlohmann::json previous = nlohmann::json::parse(*stored, nullptr, false);
  if (previous == fingerprint) return;
  std::vector<std::string> differences;
  Differences(previous.is_discarded() ? nlohmann::json() : previous, fingerprint, "", &differences);
  std::string list;
  for (const std::string& d : differences) list += "\n  " + d;
  throw InvalidArgument(fmt::format(
      "the database holds {} results made from another input or with other options; reusing "
      "them would mix old and new results. What differs (stored -> now):{}\nUse a new output "
      "folder (-o), or --overwrite to start this one again",
      stage, list));
}

}  // namespace loopsfm
