#include "loopsfm/matching/pair_selection.h"

#include <algorithm>
#include <unordered_set>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

void CheckImageIds(const std::vector<image_t>& image_ids) {
  std::unordered_set<image_t> seen;
  seen.reserve(image_ids.size());
  for (const image_t id : image_ids) {
    LOOPSFM_REQUIRE_OPTION(id != kInvalidImageId,
                           "image id list contains kInvalidImageId; pass only valid image ids");
    LOOPSFM_REQUIRE_OPTION(seen.insert(id).second,
                           "image id {} appears twice in the image list; pass each image once", id);
  }
}

}  // namespace

void SequentialPairingOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(overlap >= 1, "sequential overlap must be at least 1, got {}", overlap);
  LOOPSFM_REQUIRE_OPTION(initial_overlap >= overlap,
                         "sequential initial_overlap ({}) must be at least overlap ({})",
                         initial_overlap, overlap);
  LOOPSFM_REQUIRE_OPTION(num_initial_frames >= 0,
                         "sequential num_initial_frames must be non-negative, got {}",
                         num_initial_frames);
  LOOPSFM_REQUIRE_OPTION(overlap <= 62 || !quadratic_overlap,
                         "sequential overlap must be at most 62 with quadratic_overlap, got {}",
                         overlap);
}

std::vector<ImagePair> SequentialPairs(const std::vector<image_t>& ordered_image_ids,
                                       const SequentialPairingOptions& options) {
  options.Check();
  CheckImageIds(ordered_image_ids);
  const int64_t n = static_cast<int64_t>(ordered_image_ids.size());
  std::vector<ImagePair> pairs;
  pairs.reserve(static_cast<size_t>(n) * options.overlap);
  std::vector<int64_t> partners;
  for (int64_t i = 0; i < n; ++i) {
    const int64_t window = i < options.num_initial_frames ? options.initial_overlap
                                                          : options.overlap;
    partners.clear();
    for (int64_t j = i + 1; j <= std::min(n - 1, i + window); ++j) partners.push_back(j);
    if (options.quadratic_overlap) {
      // i + 2^k for the steps beyond the linear window; these never repeat a linear partner.
      for (int k = 0; k < options.overlap; ++k) {
        const int64_t j = i + (int64_t{1} << k);
        if (j >= n) break;
        if (j > i + window) partners.push_back(j);
      }
    }
    for (const int64_t j : partners) pairs.emplace_back(ordered_image_ids[i], ordered_image_ids[j]);
  }
  return pairs;
}

std::vector<ImagePair> ExhaustivePairs(const std::vector<image_t>& image_ids) {
  CheckImageIds(image_ids);
  const size_t n = image_ids.size();
  std::vector<ImagePair> pairs;
  pairs.reserve(n * (n > 0 ? n - 1 : 0) / 2);
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = i + 1; j < n; ++j) pairs.emplace_back(image_ids[i], image_ids[j]);
  }
  return pairs;
}

}  // namespace loopsfm
