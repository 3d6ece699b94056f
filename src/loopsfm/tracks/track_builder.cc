#include "loopsfm/tracks/track_builder.h"

#include <algorithm>

#include "loopsfm/math/union_find.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

void TrackBuildOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_track_length >= 2, "minimum track length must be at least 2, got {}",
                         min_track_length);
}

std::vector<Track> BuildTracks(const std::unordered_map<image_t, size_t>& num_points2D,
                               const std::vector<VerifiedPairMatches>& pairs,
                               const TrackBuildOptions& options, TrackBuildReport* report) {
  options.Check();
  // Dense feature index: offset of each image's first feature, images in id order so the
  // output does not depend on hash order.
  std::vector<image_t> image_ids;
  image_ids.reserve(num_points2D.size());
  for (const auto& [image_id, count] : num_points2D) image_ids.push_back(image_id);
  std::sort(image_ids.begin(), image_ids.end());
  std::unordered_map<image_t, size_t> offset;
  std::vector<image_t> owner_image;  // per image slot, for decoding
  std::vector<size_t> starts;
  size_t total = 0;
  for (image_t id : image_ids) {
    offset[id] = total;
    starts.push_back(total);
    owner_image.push_back(id);
    total += num_points2D.at(id);
  }

  UnionFind sets(total);
  std::vector<bool> used(total, false);
  TrackBuildReport local;
  for (const auto& p : pairs) {
    const size_t o1 = offset.at(p.pair.image_id1), o2 = offset.at(p.pair.image_id2);
    const size_t n1 = num_points2D.at(p.pair.image_id1), n2 = num_points2D.at(p.pair.image_id2);
    ++local.num_pairs;
    for (const FeatureMatch& m : *p.matches) {
      LOOPSFM_CHECK(m.point2D_idx1 < n1 && m.point2D_idx2 < n2);
      sets.Union(o1 + m.point2D_idx1, o2 + m.point2D_idx2);
      used[o1 + m.point2D_idx1] = used[o2 + m.point2D_idx2] = true;
      ++local.num_matches;
    }
  }

  // Group features by root, in feature order (so tracks are sorted by first element).
  std::unordered_map<size_t, size_t> track_of_root;
  std::vector<Track> tracks;
  size_t slot = 0;
  for (size_t f = 0; f < total; ++f) {
    while (slot + 1 < starts.size() && starts[slot + 1] <= f) ++slot;
    if (!used[f]) continue;
    const size_t root = sets.Find(f);
    auto [it, inserted] = track_of_root.try_emplace(root, tracks.size());
    if (inserted) tracks.emplace_back();
    tracks[it->second].elements.push_back(
        {owner_image[slot], static_cast<point2D_t>(f - starts[slot])});
  }

  std::vector<Track> kept;
  kept.reserve(tracks.size());
  for (Track& track : tracks) {
    // Elements are in image order already; a conflict is two elements of one image.
    bool conflict = false;
    for (size_t i = 1; i < track.elements.size() && !conflict; ++i) {
      conflict = track.elements[i].image_id == track.elements[i - 1].image_id;
    }
    if (conflict) {
      ++local.num_conflicting_tracks;
    } else if (track.Length() < static_cast<size_t>(options.min_track_length)) {
      ++local.num_short_tracks;
    } else {
      ++local.length_histogram[track.Length()];
      kept.push_back(std::move(track));
    }
  }
  local.num_tracks = kept.size();
  size_t sum = 0;
  for (const auto& [length, count] : local.length_histogram) sum += length * count;
  local.mean_track_length = kept.empty() ? 0.0 : double(sum) / kept.size();
  if (report) *report = std::move(local);
  return kept;
}

}  // namespace loopsfm
