// The lowres pairing strategy: every pair is first matched on each frame's largest-scale
// features (a few hundred), which is cheap, and only pairs with enough matches there are
// matched in full.

#include <numeric>

#include <tbb/parallel_for.h>

#include "loopsfm/pipeline/match.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/progress.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// Descriptors of the `count` largest-scale keypoints.
FeatureDescriptors LargestScaleDescriptors(const FeatureSet& features, int count) {
  std::vector<size_t> order(features.Size());
  std::iota(order.begin(), order.end(), size_t{0});
  const size_t keep = std::min<size_t>(count, order.size());
  std::partial_sort(order.begin(), order.begin() + keep, order.end(), [&](size_t a, size_t b) {
    return features.keypoints[a].Scale() > features.keypoints[b].Scale();
  });
  FeatureDescriptors subset(keep, kDescriptorDim);
  for (size_t i = 0; i < keep; ++i) subset.row(i) = features.descriptors.row(order[i]);
  return subset;
}

}  // namespace

void MatchLowResPrefiltered(Database& database, const std::vector<image_t>& ordered_ids,
                            const MatchOptions& options, PairMatcher& matcher,
                            MatchReport* report) {
  Timer timer;
  std::unordered_map<image_t, FeatureDescriptors> small;
  for (image_t id : ordered_ids) {
    small.emplace(id, LargestScaleDescriptors(database.ReadFeatures(id), options.lowres_num_features));
  }
  std::vector<ImagePair> candidates;
  for (const ImagePair& pair : ExhaustivePairs(ordered_ids)) {
    if (!database.ExistsMatches(pair.image_id1, pair.image_id2)) candidates.push_back(pair);
  }
  std::vector<char> pass(candidates.size(), 0);
  {
    Progress progress("prefilter", candidates.size(),
                      options.show_progress && !candidates.empty(), options.hooks);
    tbb::parallel_for(size_t{0}, candidates.size(), [&](size_t k) {
      const auto matches = MatchDescriptors(small.at(candidates[k].image_id1),
                                            small.at(candidates[k].image_id2), options.matcher);
      pass[k] = static_cast<int>(matches.size()) >= options.lowres_min_matches;
      progress.Advance();
    });
  }
  std::vector<ImagePair> full;
  {
    Database::Transaction transaction(database);
    for (size_t k = 0; k < candidates.size(); ++k) {
      if (pass[k]) {
        full.push_back(candidates[k]);
      } else {
        database.WriteMatches(candidates[k].image_id1, candidates[k].image_id2, {});
      }
    }
    transaction.Commit();
  }
  report->lowres_prefilter_seconds = timer.ElapsedSeconds();
  report->lowres_num_passed = full.size();
  spdlog::info("lowres: {} of {} pairs passed the {}-feature prefilter ({:.1f} s)", full.size(),
               candidates.size(), options.lowres_num_features, report->lowres_prefilter_seconds);
  report->num_pairs += candidates.size() - full.size();
  matcher.Match(full, report);
}

}  // namespace loopsfm
