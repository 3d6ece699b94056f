#pragma once
// What a stage's stored results depend on, kept in the database (loopsfm_meta), so a rerun
// into the same output folder with another input or other options is refused instead of
// silently mixing old results with new ones:
//   extract   the source (file or folder name and size), frame selection, SIFT options,
//             camera model and given intrinsics: every stored keypoint depends on them;
//   match     descriptor matching and geometric verification options: every stored pair
//             does. Which pairs are matched is not part of it: pairs of another strategy
//             add to the stored ones, as COLMAP's matchers do on one database.
// A database written before fingerprints existed gets one on its next run.

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "loopsfm/pipeline/extract.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/storage/database.h"

namespace loopsfm {

nlohmann::json ExtractFingerprint(const std::filesystem::path& input, const ExtractOptions& options);
nlohmann::json MatchFingerprint(const MatchOptions& options);

// Stores `fingerprint` under "<stage>_fingerprint" (stage "extract" or "match") when the
// database holds none (with a warning when it holds that stage's results: they cannot be
// checked and are taken as made with these options); throws
// InvalidArgument naming each difference (stored value, new value) and the ways out when it
// holds another.
void CheckFingerprint(Database& database, const std::string& stage,
                      const nlohmann::json& fingerprint);

}  // namespace loopsfm
