#include "loopsfm/tracks/track_builder.h"

#include <algorithm>
#include <iterator>
#include <numeric>

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

  // A component that holds two features of one image has a wrong match somewhere. Split
  // it: re-join its matches, those of the pairs with most matches first (a strong pair is
  // less likely to hold the wrong one), skipping any match that would put two features of
  // one image into one track. The component's consistent parts survive as tracks.
  std::vector<std::vector<image_t>> component_images(total);
  std::vector<char> conflicting(total, 0);
  {
    size_t image_slot = 0;
    for (size_t f = 0; f < total; ++f) {
      while (image_slot + 1 < starts.size() && starts[image_slot + 1] <= f) ++image_slot;
      if (!used[f]) continue;
      auto& images = component_images[sets.Find(f)];
      if (std::find(images.begin(), images.end(), owner_image[image_slot]) != images.end()) {
        conflicting[sets.Find(f)] = 1;
      }
      images.push_back(owner_image[image_slot]);
    }
  }
  for (size_t root = 0; root < total; ++root) local.num_conflicting_tracks += conflicting[root];
  std::vector<size_t> pair_order(pairs.size());
  std::iota(pair_order.begin(), pair_order.end(), size_t{0});
  std::stable_sort(pair_order.begin(), pair_order.end(), [&](size_t a, size_t b) {
    return pairs[a].matches->size() > pairs[b].matches->size();
  });
  UnionFind parts(total);
  std::unordered_map<size_t, std::vector<image_t>> part_images;  // root -> sorted image ids
  auto images_of = [&](size_t feature, image_t image) -> std::vector<image_t>& {
    auto [it, inserted] = part_images.try_emplace(parts.Find(feature));
    if (inserted) it->second = {image};
    return it->second;
  };
  for (size_t p : pair_order) {
    const auto& pair = pairs[p];
    const size_t o1 = offset.at(pair.pair.image_id1), o2 = offset.at(pair.pair.image_id2);
    for (const FeatureMatch& m : *pair.matches) {
      const size_t a = o1 + m.point2D_idx1, b = o2 + m.point2D_idx2;
      if (!conflicting[sets.Find(a)]) continue;
      const size_t ra = parts.Find(a), rb = parts.Find(b);
      if (ra == rb) continue;
      std::vector<image_t> ia = images_of(a, pair.pair.image_id1);
      std::vector<image_t> ib = images_of(b, pair.pair.image_id2);
      std::vector<image_t> joined;
      std::set_union(ia.begin(), ia.end(), ib.begin(), ib.end(), std::back_inserter(joined));
      if (joined.size() < ia.size() + ib.size()) {
        ++local.num_dropped_matches;
        continue;
      }
      part_images.erase(ra);
      part_images.erase(rb);
      part_images[parts.Union(ra, rb)] = std::move(joined);
    }
  }

  // Group features by root (or by part root in split components), in feature order, so
  // tracks are sorted by their first element.
  std::unordered_map<size_t, size_t> track_of_root;
  std::vector<Track> tracks;
  size_t slot = 0;
  for (size_t f = 0; f < total; ++f) {
    while (slot + 1 < starts.size() && starts[slot + 1] <= f) ++slot;
    if (!used[f]) continue;
    const size_t root = sets.Find(f);
    const size_t key = conflicting[root] ? total + parts.Find(f) : root;
    auto [it, inserted] = track_of_root.try_emplace(key, tracks.size());
    if (inserted) tracks.emplace_back();
    tracks[it->second].elements.push_back(
        {owner_image[slot], static_cast<point2D_t>(f - starts[slot])});
  }

  std::vector<Track> kept;
  kept.reserve(tracks.size());
  for (Track& track : tracks) {
    if (track.Length() < static_cast<size_t>(options.min_track_length)) {
      ++local.num_short_tracks;
      continue;
    }
    // Elements are in image order; split parts hold one feature per image.
    for (size_t i = 1; i < track.elements.size(); ++i) {
      LOOPSFM_CHECK(track.elements[i].image_id != track.elements[i - 1].image_id);
    }
    ++local.length_histogram[track.Length()];
    kept.push_back(std::move(track));
  }
  local.num_tracks = kept.size();
  size_t sum = 0;
  for (const auto& [length, count] : local.length_histogram) sum += length * count;
  local.mean_track_length = kept.empty() ? 0.0 : double(sum) / kept.size();
  if (report) *report = std::move(local);
  return kept;
}

}  // namespace loopsfm
