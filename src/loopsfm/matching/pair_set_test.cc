#include "loopsfm/matching/pair_set.h"

#include <gtest/gtest.h>

namespace loopsfm {
namespace {

TEST(IndexPairSet, PairsAreUnorderedAndCountedOnce) {
  IndexPairSet set(5);
  EXPECT_TRUE(set.Insert(3, 1));
  EXPECT_FALSE(set.Insert(1, 3));
  EXPECT_TRUE(set.Insert(0, 4));
  EXPECT_EQ(set.Size(), 2u);
  EXPECT_TRUE(set.Contains(1, 3));
  EXPECT_TRUE(set.Contains(3, 1));
  EXPECT_FALSE(set.Contains(1, 2));
  // Out of range or i == j: never contained.
  EXPECT_FALSE(set.Contains(-1, 3));
  EXPECT_FALSE(set.Contains(1, 5));
  EXPECT_FALSE(set.Contains(2, 2));
  EXPECT_EQ(set.Partners(1), std::vector<int>{3});
  EXPECT_EQ(set.Partners(3), std::vector<int>{1});
  EXPECT_TRUE(set.Partners(2).empty());
  EXPECT_EQ(set.SortedPairs(), (std::vector<std::pair<int, int>>{{0, 4}, {1, 3}}));
}

TEST(IndexPairSet, LargeIndicesDoNotCollide) {
  const int n = 200000;
  IndexPairSet set(n);
  EXPECT_TRUE(set.Insert(n - 1, n - 2));
  EXPECT_TRUE(set.Insert(1, n - 2));
  EXPECT_FALSE(set.Contains(n - 1, 1));
  EXPECT_TRUE(set.Contains(n - 2, n - 1));
  EXPECT_EQ(set.SortedPairs().back(), std::make_pair(n - 2, n - 1));
}

}  // namespace
}  // namespace loopsfm
