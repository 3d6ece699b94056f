#include "loopsfm/math/graph.h"

#include <gtest/gtest.h>

namespace loopsfm {
namespace {

TEST(ConnectedComponents, LabelsByDecreasingSize) {
  // {0, 1}, {2, 3, 4}, {5}
  const GraphComponents c = ConnectedComponents(6, {{0, 1}, {3, 2}, {4, 3}});
  ASSERT_EQ(c.NumComponents(), 3);
  EXPECT_EQ(c.sizes, (std::vector<int>{3, 2, 1}));
  EXPECT_EQ(c.label, (std::vector<int>{1, 1, 0, 0, 0, 2}));
  EXPECT_EQ(c.LargestSize(), 3);
}

TEST(ConnectedComponents, TiesByFirstVertexAndMatrixInput) {
  Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic> a =
      Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic>::Constant(4, 4, false);
  a(2, 3) = a(3, 2) = true;
  a(0, 1) = a(1, 0) = true;
  const GraphComponents c = ConnectedComponents(a);
  EXPECT_EQ(c.label, (std::vector<int>{0, 0, 1, 1}));
  EXPECT_EQ(ConnectedComponents(0, {}).NumComponents(), 0);
}

}  // namespace
}  // namespace loopsfm
