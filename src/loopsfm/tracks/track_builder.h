#pragma once
// Tracks from verified matches: union-find over all features, joined along every verified
// inlier match. A component that holds two different features of one image is a conflict
// (a wrong match somewhere along it): it is split into consistent parts by joining its
// matches again, strongest pairs first, and leaving out every match that would put two
// features of one image together. Long tracks hold drift down and carry loops, so they are
// split, not dropped. The result is the track set as built from matching, before any
// mapper prunes it; loop closing re-uses it.

#include <map>
#include <unordered_map>
#include <vector>

#include "loopsfm/scene/features.h"
#include "loopsfm/scene/track.h"

namespace loopsfm {

struct TrackBuildOptions {
  // Tracks shorter than this are dropped (2 keeps every verified match).
  int min_track_length = 2;
  void Check() const;
};

struct TrackBuildReport {
  size_t num_pairs = 0;
  size_t num_matches = 0;
  size_t num_tracks = 0;
  // Components with a conflict (split into consistent parts), and the matches left out.
  size_t num_conflicting_tracks = 0;
  size_t num_dropped_matches = 0;
  size_t num_short_tracks = 0;
  // Track length -> number of tracks of that length.
  std::map<size_t, size_t> length_histogram;
  double mean_track_length = 0.0;
};

struct VerifiedPairMatches {
  ImagePair pair;
  // Indices into pair.image_id1's and pair.image_id2's keypoints, in that order.
  const FeatureMatches* matches = nullptr;
};

// num_points2D maps every image id that appears in `pairs` to its keypoint count.
// Tracks come out sorted by their first element; elements sorted by image id.
std::vector<Track> BuildTracks(const std::unordered_map<image_t, size_t>& num_points2D,
                               const std::vector<VerifiedPairMatches>& pairs,
                               const TrackBuildOptions& options, TrackBuildReport* report);

}  // namespace loopsfm
