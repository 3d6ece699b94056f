#include "loopsfm/feature/sift.h"

#include <gtest/gtest.h>

#include <algorithm>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Smoothed noise with blobs at many scales: a good SIFT test pattern.
cv::Mat Texture(int width, int height) {
  cv::Mat acc = cv::Mat::zeros(height, width, CV_32F);
  cv::RNG rng(7);
  for (int cell : {4, 8, 16, 32}) {
    cv::Mat small(height / cell + 2, width / cell + 2, CV_32F);
    rng.fill(small, cv::RNG::UNIFORM, 0.0f, 1.0f);
    cv::Mat up;
    cv::resize(small, up, cv::Size(small.cols * cell, small.rows * cell), 0, 0, cv::INTER_CUBIC);
    acc += up(cv::Rect(0, 0, width, height));
  }
  cv::Mat out;
  cv::normalize(acc, acc, 0, 255, cv::NORM_MINMAX);
  acc.convertTo(out, CV_8U);
  cv::cvtColor(out, out, cv::COLOR_GRAY2BGR);
  return out;
}

TEST(Sift, KeypointsFollowColmapPixelConventionAndShiftWithTheImage) {
  const cv::Mat image = Texture(320, 240);
  SiftOptions options;
  const FeatureSet a = ExtractSift(image, options);
  ASSERT_GT(a.Size(), 100u);
  EXPECT_EQ(a.descriptors.rows(), static_cast<long>(a.Size()));
  // Shift by exactly 10 px: matched keypoints must move by 10 px.
  cv::Mat shifted;
  const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, 10, 0, 1, 0);
  cv::warpAffine(image, shifted, m, image.size(), cv::INTER_NEAREST, cv::BORDER_REFLECT);
  const FeatureSet b = ExtractSift(shifted, options);
  int agree = 0, checked = 0;
  for (size_t i = 0; i < a.Size(); ++i) {
    const auto& kp = a.keypoints[i];
    if (kp.x < 30 || kp.x > 280 || kp.y < 20 || kp.y > 220) continue;
    ++checked;
    for (const auto& other : b.keypoints) {
      if (std::abs(other.x - kp.x - 10) < 0.05 && std::abs(other.y - kp.y) < 0.05) {
        ++agree;
        break;
      }
    }
  }
  EXPECT_GT(agree, 0.8 * checked);
}

TEST(Sift, MaxFeaturesKeepsTheStrongest) {
  SiftOptions options;
  options.max_features = 50;
  const FeatureSet features = ExtractSift(Texture(320, 240), options);
  EXPECT_EQ(features.Size(), 50u);
}

// The plain two-pass way: detect every keypoint, keep the strongest (ties in detection order),
// then compute their descriptors on a second scale space.
FeatureDescriptors TwoPassDescriptors(const cv::Mat& grey, const SiftOptions& options,
                                      std::vector<cv::KeyPoint>* keypoints) {
  auto sift = cv::SIFT::create(0, options.num_octave_layers, options.contrast_threshold,
                               options.edge_threshold);
  sift->detect(grey, *keypoints);
  if (static_cast<int>(keypoints->size()) > options.max_features) {
    std::stable_sort(keypoints->begin(), keypoints->end(),
                     [](const cv::KeyPoint& a, const cv::KeyPoint& b) {
                       return a.response > b.response;
                     });
    keypoints->resize(options.max_features);
  }
  cv::Mat descriptors;
  sift->compute(grey, *keypoints, descriptors);
  return QuantizeDescriptors(descriptors, options.root_sift);
}

TEST(Sift, OnePassEqualsDetectThenComputeWithAndWithoutTheCap) {
  cv::Mat grey;
  cv::cvtColor(Texture(320, 240), grey, cv::COLOR_BGR2GRAY);
  for (int max_features : {100000, 300}) {
    SiftOptions options;
    options.max_features = max_features;
    std::vector<cv::KeyPoint> expected_keypoints;
    const FeatureDescriptors expected = TwoPassDescriptors(grey, options, &expected_keypoints);
    const FeatureSet features = ExtractSift(grey, options);
    ASSERT_EQ(features.Size(), expected_keypoints.size()) << max_features;
    if (max_features == 300) ASSERT_EQ(features.Size(), 300u);
    else ASSERT_GT(features.Size(), 300u);
    for (size_t i = 0; i < features.Size(); ++i) {
      EXPECT_FLOAT_EQ(features.keypoints[i].x, expected_keypoints[i].pt.x + 0.5f) << i;
      EXPECT_FLOAT_EQ(features.keypoints[i].y, expected_keypoints[i].pt.y + 0.5f) << i;
    }
    EXPECT_TRUE(features.descriptors == expected) << max_features;
  }
}

TEST(Sift, RootSiftDescriptorsHaveUnitNormBeforeQuantisation) {
  cv::Mat d(1, 128, CV_32F);
  cv::RNG(3).fill(d, cv::RNG::UNIFORM, 0.0f, 100.0f);
  for (bool root : {false, true}) {
    const FeatureDescriptors q = QuantizeDescriptors(d, root);
    const double norm = q.row(0).cast<double>().norm() / 512.0;
    EXPECT_NEAR(norm, 1.0, 0.02) << "root_sift=" << root;
  }
}

TEST(Sift, UpscaleMapsKeypointsBackToOriginalPixels) {
  const cv::Mat image = Texture(200, 160);
  SiftOptions options;
  options.upscale = 2.0;
  std::vector<Eigen::Matrix<uint8_t, 3, 1>> colors;
  const FeatureSet features = ExtractSift(image, options, &colors);
  ASSERT_GT(features.Size(), 50u);
  ASSERT_EQ(colors.size(), features.Size());
  for (const auto& kp : features.keypoints) {
    EXPECT_GE(kp.x, 0.0f);
    EXPECT_LE(kp.x, 200.0f);
    EXPECT_LE(kp.y, 160.0f);
  }
  options.upscale = 0.5;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

TEST(Sift, LargeFramesAreDownscaledToMaxImageSizeAndKeypointsMappedBack) {
  // A 1600 x 1200 frame with max_image_size 400 gives the features of the frame shrunk to
  // 400 x 300, keypoints four times as far from the origin (pixel borders scale exactly).
  const cv::Mat large = Texture(1600, 1200);
  SiftOptions options;
  options.max_image_size = 400;
  const SiftInput input = PrepareSiftInput(large, options);
  EXPECT_EQ(input.grey.cols, 400);
  EXPECT_EQ(input.grey.rows, 300);
  EXPECT_DOUBLE_EQ(input.scale_x, 0.25);
  EXPECT_DOUBLE_EQ(input.scale_y, 0.25);
  const FeatureSet from_large = ExtractSift(large, options);

  cv::Mat grey, small;
  cv::cvtColor(large, grey, cv::COLOR_BGR2GRAY);
  cv::resize(grey, small, cv::Size(400, 300), 0, 0, cv::INTER_AREA);
  const FeatureSet from_small = ExtractSift(small, SiftOptions());
  ASSERT_GT(from_small.Size(), 100u);
  ASSERT_EQ(from_large.Size(), from_small.Size());
  EXPECT_EQ(from_large.descriptors, from_small.descriptors);
  float max_x = 0.0f;
  for (size_t i = 0; i < from_small.Size(); ++i) {
    EXPECT_NEAR(from_large.keypoints[i].x, 4.0f * from_small.keypoints[i].x, 1e-3f);
    EXPECT_NEAR(from_large.keypoints[i].y, 4.0f * from_small.keypoints[i].y, 1e-3f);
    EXPECT_NEAR(from_large.keypoints[i].Scale(), 4.0f * from_small.keypoints[i].Scale(),
                1e-3f);
    max_x = std::max(max_x, from_large.keypoints[i].x);
  }
  EXPECT_GT(max_x, 1500.0f) << "keypoints are not in the large frame's pixels";

  // Frames within the limit are used as they are.
  EXPECT_EQ(PrepareSiftInput(Texture(320, 240), SiftOptions()).grey.cols, 320);
  options.max_image_size = 0;
  EXPECT_THROW(options.Check(), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
