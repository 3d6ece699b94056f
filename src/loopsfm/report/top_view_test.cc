#include "loopsfm/report/top_view.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include <opencv2/imgcodecs.hpp>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

TEST(TopView, DrawsPathsInTheirPlaneAndLegend) {
  // A circle in the x-z plane (y is down, as for a camera walking on flat ground).
  TopViewPath circle{"ground truth", {}, {0, 0, 255}};
  for (int i = 0; i <= 100; ++i) {
    const double a = 2 * M_PI * i / 100;
    circle.centres.emplace_back(10 * std::cos(a), 0.1 * std::sin(7 * a), 10 * std::sin(a));
  }
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / "loopsfm_top_view_test.png";
  WriteTopView(file, {circle}, {}, "circle", 400);
  const cv::Mat image = cv::imread(file.string());
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, 400);
  // Seen from the top, the circle is round: pure blue pixels span as many rows as columns
  // below the legend.
  int min_row = image.rows, max_row = 0, min_col = image.cols, max_col = 0;
  for (int r = 100; r < image.rows; ++r) {
    for (int c = 0; c < image.cols; ++c) {
      const cv::Vec3b p = image.at<cv::Vec3b>(r, c);
      if (p[0] > 200 && p[1] < 60 && p[2] < 60) {
        min_row = std::min(min_row, r), max_row = std::max(max_row, r);
        min_col = std::min(min_col, c), max_col = std::max(max_col, c);
      }
    }
  }
  ASSERT_GT(max_col, min_col);
  EXPECT_NEAR(static_cast<double>(max_row - min_row) / (max_col - min_col), 1.0, 0.1);
  std::filesystem::remove(file);
}

TEST(TopView, NothingToPlotIsAnError) {
  EXPECT_THROW(WriteTopView("x.png", {{"empty", {}, {0, 0, 0}}}, {}, "t"), InvalidArgument);
  TopViewPath path{"p", {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}}, {0, 0, 0}};
  EXPECT_THROW(WriteTopView("/nonexistent-folder/x.png", {path}, {}, "t"), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
