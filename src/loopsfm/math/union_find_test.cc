#include "loopsfm/math/union_find.h"

#include <gtest/gtest.h>

#include "loopsfm/math/random.h"

namespace loopsfm {
namespace {

TEST(UnionFind, JoinsTransitivelyAndCountsSizes) {
  UnionFind uf(6);
  uf.Union(0, 1);
  uf.Union(2, 3);
  uf.Union(1, 3);
  EXPECT_EQ(uf.Find(0), uf.Find(2));
  EXPECT_NE(uf.Find(0), uf.Find(4));
  EXPECT_EQ(uf.SetSize(3), 4u);
  EXPECT_EQ(uf.SetSize(5), 1u);
}

TEST(Random, DerivedStreamsAreReproducibleAndDistinct) {
  const Random base(42);
  Random a = base.Derive(3), b = base.Derive(3), c = base.Derive(4);
  const auto x = a.UniformInt(0, 1 << 30);
  EXPECT_EQ(x, b.UniformInt(0, 1 << 30));
  EXPECT_NE(x, c.UniformInt(0, 1 << 30));
  const auto sample = Random(1).Sample(10, 10);
  std::vector<bool> seen(10, false);
  for (auto i : sample) seen[i] = true;
  EXPECT_EQ(std::count(seen.begin(), seen.end(), true), 10);
}

}  // namespace
}  // namespace loopsfm
