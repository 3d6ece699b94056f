#include "loopsfm/matching/pair_selection.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <set>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

std::vector<image_t> Ids(int n, image_t first = 1) {
  std::vector<image_t> ids(n);
  std::iota(ids.begin(), ids.end(), first);
  return ids;
}

// Number of pairs (i, j), i < j < n, with j - i <= window(i).
template <typename Window>
size_t CountWindowPairs(int n, Window window) {
  size_t count = 0;
  for (int i = 0; i < n; ++i) count += std::min(n - 1 - i, window(i));
  return count;
}

TEST(SequentialPairs, PlainOverlapMatchesFollowingFrames) {
  SequentialPairingOptions options;
  options.overlap = 3;
  options.initial_overlap = 3;
  options.num_initial_frames = 0;
  const std::vector<ImagePair> pairs = SequentialPairs(Ids(6), options);
  const std::vector<ImagePair> expected = {{1, 2}, {1, 3}, {1, 4}, {2, 3}, {2, 4}, {2, 5},
                                           {3, 4}, {3, 5}, {3, 6}, {4, 5}, {4, 6}, {5, 6}};
  EXPECT_EQ(pairs, expected);
}

TEST(SequentialPairs, InitialFramesGetTheWiderOverlap) {
  SequentialPairingOptions options;  // overlap 10, initial_overlap 30, 10 initial frames
  const int n = 100;
  const std::vector<ImagePair> pairs = SequentialPairs(Ids(n, 0), options);
  EXPECT_EQ(pairs.size(), CountWindowPairs(n, [](int i) { return i < 10 ? 30 : 10; }));
  const std::set<ImagePair> unique(pairs.begin(), pairs.end());
  EXPECT_EQ(unique.size(), pairs.size());
  EXPECT_TRUE(unique.count({0, 30}));   // frame 0 reaches 30 frames ahead
  EXPECT_FALSE(unique.count({0, 31}));
  EXPECT_TRUE(unique.count({9, 39}));   // the last initial frame too
  EXPECT_FALSE(unique.count({10, 21}));  // later frames use the normal overlap
  EXPECT_TRUE(unique.count({10, 20}));
  for (const ImagePair& p : pairs) EXPECT_LT(p.image_id1, p.image_id2);
}

TEST(SequentialPairs, OrderFollowsTheListNotTheIds) {
  SequentialPairingOptions options;
  options.overlap = 1;
  options.initial_overlap = 1;
  const std::vector<ImagePair> pairs = SequentialPairs({7, 3, 9, 1}, options);
  const std::vector<ImagePair> expected = {{3, 7}, {3, 9}, {1, 9}};
  EXPECT_EQ(pairs, expected);
  for (const ImagePair& p : pairs) EXPECT_LT(p.image_id1, p.image_id2);
}

TEST(SequentialPairs, QuadraticOverlapAddsPowerOfTwoStepsWithoutDuplicates) {
  SequentialPairingOptions options;
  options.overlap = 3;
  options.initial_overlap = 3;
  options.num_initial_frames = 0;
  options.quadratic_overlap = true;
  const std::vector<ImagePair> pairs = SequentialPairs(Ids(20, 0), options);
  const std::set<ImagePair> unique(pairs.begin(), pairs.end());
  EXPECT_EQ(unique.size(), pairs.size());
  // Steps 1, 2, 3 (linear) and 4 (= 2^2; 2^0 and 2^1 are already linear).
  EXPECT_EQ(pairs.size(), CountWindowPairs(20, [](int) { return 3; }) + (20 - 4));
  EXPECT_TRUE(unique.count({0, 4}));
  EXPECT_FALSE(unique.count({0, 5}));
}

TEST(SequentialPairs, SmallInputs) {
  SequentialPairingOptions options;
  EXPECT_TRUE(SequentialPairs({}, options).empty());
  EXPECT_TRUE(SequentialPairs({5}, options).empty());
  EXPECT_EQ(SequentialPairs({5, 2}, options), std::vector<ImagePair>({{2, 5}}));
}

TEST(SequentialPairs, RejectsBadOptionsAndIds) {
  SequentialPairingOptions options;
  options.overlap = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options.overlap = 10;
  options.initial_overlap = 5;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options.initial_overlap = 30;
  options.num_initial_frames = -1;
  EXPECT_THROW(options.Check(), InvalidArgument);
  options.num_initial_frames = 10;
  EXPECT_NO_THROW(options.Check());
  EXPECT_THROW(SequentialPairs({1, 2, 1}, options), InvalidArgument);
  EXPECT_THROW(SequentialPairs({1, kInvalidImageId}, options), InvalidArgument);
}

TEST(ExhaustivePairs, AllUnorderedPairsOnce) {
  const int n = 37;
  const std::vector<ImagePair> pairs = ExhaustivePairs(Ids(n, 100));
  EXPECT_EQ(pairs.size(), static_cast<size_t>(n * (n - 1) / 2));
  const std::set<ImagePair> unique(pairs.begin(), pairs.end());
  EXPECT_EQ(unique.size(), pairs.size());
  for (const ImagePair& p : pairs) {
    EXPECT_LT(p.image_id1, p.image_id2);
    EXPECT_GE(p.image_id1, 100u);
    EXPECT_LT(p.image_id2, 100u + n);
  }
  EXPECT_TRUE(ExhaustivePairs({}).empty());
  EXPECT_TRUE(ExhaustivePairs({4}).empty());
  EXPECT_THROW(ExhaustivePairs({4, 4}), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
