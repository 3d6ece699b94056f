#include "loopsfm/util/types.h"

#include <gtest/gtest.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

TEST(Types, PairIdRoundTripsAndIsSymmetric) {
  const image_pair_t id = PairToPairId(7, 3);
  EXPECT_EQ(id, PairToPairId(3, 7));
  EXPECT_EQ(id, 3ull * 2147483647ull + 7ull);  // COLMAP's packing, smaller id first
  const ImagePair pair = PairIdToPair(id);
  EXPECT_EQ(pair.image_id1, 3u);
  EXPECT_EQ(pair.image_id2, 7u);
  EXPECT_TRUE(SwapImagePair(7, 3));
  EXPECT_FALSE(SwapImagePair(3, 7));
}

TEST(Errors, RequireOptionThrowsReadableMessage) {
  const int overlap = -1;
  try {
    LOOPSFM_REQUIRE_OPTION(overlap > 0, "--overlap must be positive, got {}", overlap);
    FAIL() << "expected InvalidArgument";
  } catch (const InvalidArgument& e) {
    EXPECT_STREQ(e.what(), "--overlap must be positive, got -1");
  }
}

}  // namespace
}  // namespace loopsfm
