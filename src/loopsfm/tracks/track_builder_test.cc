#include "loopsfm/tracks/track_builder.h"

#include <gtest/gtest.h>

namespace loopsfm {
namespace {

TEST(BuildTracks, JoinsChainsAndRemovesConflicts) {
  // Images 1,2,3 with 5 features each.
  // Track A: 1:0 - 2:1 - 3:2 (consistent chain).
  // Track B: 1:3 - 2:3, 2:3 - 3:3, 3:3 - 1:4 -> holds features 3 and 4 of image 1: conflict.
  // Track C: 2:4 - 3:4 (length 2).
  const std::unordered_map<image_t, size_t> num_points2D = {{1, 5}, {2, 5}, {3, 5}};
  const FeatureMatches m12 = {{0, 1}, {3, 3}};
  const FeatureMatches m23 = {{1, 2}, {3, 3}, {4, 4}};
  const FeatureMatches m13 = {{4, 3}};
  const std::vector<VerifiedPairMatches> pairs = {
      {ImagePair(1, 2), &m12}, {ImagePair(2, 3), &m23}, {ImagePair(1, 3), &m13}};
  TrackBuildReport report;
  const auto tracks = BuildTracks(num_points2D, pairs, {}, &report);
  ASSERT_EQ(tracks.size(), 2u);
  EXPECT_EQ(tracks[0].elements,
            (std::vector<TrackElement>{{1, 0}, {2, 1}, {3, 2}}));
  EXPECT_EQ(tracks[1].elements, (std::vector<TrackElement>{{2, 4}, {3, 4}}));
  EXPECT_EQ(report.num_conflicting_tracks, 1u);
  EXPECT_EQ(report.num_matches, 6u);
  EXPECT_EQ(report.length_histogram.at(3), 1u);
  EXPECT_EQ(report.length_histogram.at(2), 1u);
  EXPECT_DOUBLE_EQ(report.mean_track_length, 2.5);
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

}  // namespace
}  // namespace loopsfm
