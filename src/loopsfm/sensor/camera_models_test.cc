#include "loopsfm/sensor/camera_models.h"

#include <gtest/gtest.h>

#include <vector>

namespace loopsfm {
namespace {

std::vector<double> ExampleParams(CameraModelId id) {
  switch (id) {
    case CameraModelId::kSimplePinhole: return {500, 320, 240};
    case CameraModelId::kPinhole: return {500, 510, 320, 240};
    case CameraModelId::kSimpleRadial: return {500, 320, 240, -0.08};
    case CameraModelId::kRadial: return {500, 320, 240, -0.08, 0.01};
    case CameraModelId::kOpenCV: return {500, 510, 320, 240, 0.0578, -0.0805, -0.00098, 0.00016};
  }
  return {};
}

class CameraModelTest : public ::testing::TestWithParam<int> {};

TEST_P(CameraModelTest, UnprojectInvertsProject) {
  const auto id = static_cast<CameraModelId>(GetParam());
  const auto params = ExampleParams(id);
  ASSERT_EQ(static_cast<int>(params.size()), CameraModelNumParams(id));
  VisitCameraModel(id, [&](auto model) {
    using Model = decltype(model);
    for (double u = -0.5; u <= 0.5; u += 0.1) {
      for (double v = -0.4; v <= 0.4; v += 0.1) {
        double x, y;
        Model::ImgFromCam(params.data(), u * 3.0, v * 3.0, 3.0, &x, &y);
        const Eigen::Vector2d uv = Model::CamFromImg(params.data(), x, y);
        EXPECT_NEAR(uv.x(), u, 1e-9);
        EXPECT_NEAR(uv.y(), v, 1e-9);
      }
    }
  });
}

TEST_P(CameraModelTest, NameRoundTrips) {
  const auto id = static_cast<CameraModelId>(GetParam());
  EXPECT_EQ(CameraModelFromName(CameraModelName(id)), id);
}

INSTANTIATE_TEST_SUITE_P(AllModels, CameraModelTest, ::testing::Range(0, 5));

TEST(CameraModels, UnknownNameIsRejected) { EXPECT_FALSE(CameraModelFromName("FISHEYE_X")); }

}  // namespace
}  // namespace loopsfm
