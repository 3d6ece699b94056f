#include "loopsfm/sensor/camera_models.h"

#include <gtest/gtest.h>

#include <vector>

#include <ceres/jet.h>

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

// Jacobian of ImgFromCam w.r.t. the point (u, v, w) and the parameters, by automatic
// differentiation (what bundle adjustment uses), against central finite differences.
TEST_P(CameraModelTest, ProjectionJacobianMatchesFiniteDifferences) {
  const auto id = static_cast<CameraModelId>(GetParam());
  const auto params = ExampleParams(id);
  VisitCameraModel(id, [&](auto model) {
    using Model = decltype(model);
    constexpr int N = Model::kNumParams + 3;
    using Jet = ceres::Jet<double, N>;
    const double point[3] = {0.4, -0.3, 2.5};
    std::vector<Jet> jet_params(Model::kNumParams);
    for (int i = 0; i < Model::kNumParams; ++i) jet_params[i] = Jet(params[i], 3 + i);
    Jet x, y;
    Model::ImgFromCam(jet_params.data(), Jet(point[0], 0), Jet(point[1], 1), Jet(point[2], 2), &x, &y);
    // All inputs in one vector: point, then parameters.
    std::vector<double> input(point, point + 3);
    input.insert(input.end(), params.begin(), params.end());
    auto project = [&](const std::vector<double>& in) {
      Eigen::Vector2d xy;
      Model::ImgFromCam(in.data() + 3, in[0], in[1], in[2], &xy.x(), &xy.y());
      return xy;
    };
    for (int k = 0; k < N; ++k) {
      const double h = 1e-6 * std::max(1.0, std::abs(input[k]));
      auto plus = input, minus = input;
      plus[k] += h;
      minus[k] -= h;
      const Eigen::Vector2d numeric = (project(plus) - project(minus)) / (2 * h);
      const double scale = std::max(1.0, numeric.norm());
      EXPECT_NEAR(x.v[k], numeric.x(), 1e-6 * scale) << Model::kName << " input " << k;
      EXPECT_NEAR(y.v[k], numeric.y(), 1e-6 * scale) << Model::kName << " input " << k;
    }
  });
}

// The Jacobian of CamFromImg (unprojection) is the inverse of the projection Jacobian on
// the normalised plane; checked by finite differences of the unprojection itself.
TEST_P(CameraModelTest, UnprojectionJacobianInvertsProjectionJacobian) {
  const auto id = static_cast<CameraModelId>(GetParam());
  const auto params = ExampleParams(id);
  VisitCameraModel(id, [&](auto model) {
    using Model = decltype(model);
    const Eigen::Vector2d uv(0.21, -0.17);
    Eigen::Vector2d xy;
    Model::ImgFromCam(params.data(), uv.x(), uv.y(), 1.0, &xy.x(), &xy.y());
    Eigen::Matrix2d project_jacobian, unproject_jacobian;
    const double h = 1e-6;
    for (int k = 0; k < 2; ++k) {
      Eigen::Vector2d d = Eigen::Vector2d::Zero();
      d[k] = h;
      Eigen::Vector2d p1, p2;
      Model::ImgFromCam(params.data(), uv.x() + d.x(), uv.y() + d.y(), 1.0, &p1.x(), &p1.y());
      Model::ImgFromCam(params.data(), uv.x() - d.x(), uv.y() - d.y(), 1.0, &p2.x(), &p2.y());
      project_jacobian.col(k) = (p1 - p2) / (2 * h);
      const double hp = 1e-4;
      Eigen::Vector2d e = Eigen::Vector2d::Zero();
      e[k] = hp;
      unproject_jacobian.col(k) =
          (Model::CamFromImg(params.data(), xy.x() + e.x(), xy.y() + e.y()) -
           Model::CamFromImg(params.data(), xy.x() - e.x(), xy.y() - e.y())) / (2 * hp);
    }
    EXPECT_LT((unproject_jacobian * project_jacobian - Eigen::Matrix2d::Identity()).norm(), 1e-6)
        << Model::kName;
  });
}

INSTANTIATE_TEST_SUITE_P(AllModels, CameraModelTest, ::testing::Range(0, 5));

TEST(CameraModels, UnknownNameIsRejected) { EXPECT_FALSE(CameraModelFromName("FISHEYE_X")); }

}  // namespace
}  // namespace loopsfm
