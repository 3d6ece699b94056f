#include "loopsfm/tracks/track_builder.h"

#include <gtest/gtest.h>

namespace loopsfm {
namespace {

TEST(BuildTracks, JoinsChainsAndSplitsConflicts) {
  // Images 1,2,3 with 5 features each.
  // Track A: 1:0 - 2:1 - 3:2 (consistent chain).
  // Track B: 1:3 - 2:3, 2:3 - 3:3, 3:3 - 1:4 -> holds features 3 and 4 of image 1: conflict.
  //   Pair (2, 3) has the most matches, then (1, 2), then (1, 3): B is re-joined in that
  //   order and the match 1:4 - 3:3 of the weakest pair is left out.
  // Track C: 2:4 - 3:4 (length 2).
  const std::unordered_map<image_t, size_t> num_points2D = {{1, 5}, {2, 5}, {3, 5}};
  const FeatureMatches m12 = {{0, 1}, {3, 3}};
  const FeatureMatches m23 = {{1, 2}, {3, 3}, {4, 4}};
  const FeatureMatches m13 = {{4, 3}};
  const std::vector<VerifiedPairMatches> pairs = {
      {ImagePair(1, 2), &m12}, {ImagePair(2, 3), &m23}, {ImagePair(1, 3), &m13}};
  TrackBuildReport report;
  const auto tracks = BuildTracks(num_points2D, pairs, {}, &report);
  ASSERT_EQ(tracks.size(), 3u);
  EXPECT_EQ(tracks[0].elements,
            (std::vector<TrackElement>{{1, 0}, {2, 1}, {3, 2}}));
  EXPECT_EQ(tracks[1].elements, (std::vector<TrackElement>{{1, 3}, {2, 3}, {3, 3}}));
  EXPECT_EQ(tracks[2].elements, (std::vector<TrackElement>{{2, 4}, {3, 4}}));
  EXPECT_EQ(report.num_conflicting_tracks, 1u);
  EXPECT_EQ(report.num_dropped_matches, 1u);
  EXPECT_EQ(report.num_short_tracks, 1u);  // 1:4, left alone
  EXPECT_EQ(report.num_matches, 6u);
  EXPECT_EQ(report.length_histogram.at(3), 2u);
  EXPECT_EQ(report.length_histogram.at(2), 1u);
  EXPECT_NEAR(report.mean_track_length, 8.0 / 3.0, 1e-12);
}

TEST(BuildTracks, MinLengthDropsShortTracks) {
  const std::unordered_map<image_t, size_t> num_points2D = {{1, 2}, {2, 2}, {3, 2}};
  const FeatureMatches m12 = {{0, 0}, {1, 1}};
  const FeatureMatches m23 = {{0, 0}};
  const std::vector<VerifiedPairMatches> pairs = {{ImagePair(1, 2), &m12},
                                                  {ImagePair(2, 3), &m23}};
  TrackBuildOptions options;
  options.min_track_length = 3;
  TrackBuildReport report;
  const auto tracks = BuildTracks(num_points2D, pairs, options, &report);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0].Length(), 3u);
  EXPECT_EQ(report.num_short_tracks, 1u);
}

TEST(BuildTracks, KeepsLongTracksWhoseConflictIsOneWeakLoopMatch) {
  // Images 1..10 in a row; feature 0 of every image is one scene point, matched between
  // neighbours (pairs with 3 matches: features 0, 1, 2). One wrong match of a weak loop pair
  // (1 match) joins feature 1 of image 10 to feature 0 of image 1 ... and feature 0 of
  // image 10 is already in the chain: a conflict. The chain must survive whole.
  std::unordered_map<image_t, size_t> num_points2D;
  for (image_t i = 1; i <= 10; ++i) num_points2D[i] = 3;
  const FeatureMatches neighbours = {{0, 0}, {1, 1}, {2, 2}};
  const FeatureMatches loop = {{0, 1}};
  std::vector<VerifiedPairMatches> pairs;
  for (image_t i = 1; i < 10; ++i) pairs.push_back({ImagePair(i, i + 1), &neighbours});
  pairs.push_back({ImagePair(1, 10), &loop});
  TrackBuildReport report;
  const auto tracks = BuildTracks(num_points2D, pairs, {}, &report);
  // Tracks of features 0 and 1 are one component (conflict), feature 2's is clean.
  EXPECT_EQ(report.num_conflicting_tracks, 1u);
  EXPECT_EQ(report.num_dropped_matches, 1u);
  ASSERT_EQ(tracks.size(), 3u);
  for (const Track& track : tracks) EXPECT_EQ(track.Length(), 10u);
}

}  // namespace
}  // namespace loopsfm
