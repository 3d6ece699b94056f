#include "loopsfm/sensor/camera_models.h"

#include <gtest/gtest.h>

#include <vector>

#include <Eigen/Geometry>
#include <ceres/jet.h>

#include "loopsfm/math/random.h"
#include "loopsfm/sensor/camera_models_test_util.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using camera_models_test::ExampleParams;
using camera_models_test::kImageHeight;
using camera_models_test::kImageWidth;

class CameraModelTest : public ::testing::TestWithParam<CameraModelId> {};

TEST_P(CameraModelTest, UnprojectInvertsProject) {
  const CameraModelId id = GetParam();
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

// Random pixels of the image: unprojected (the undistortion converges) and projected again,
// they land on themselves; random points in front of the camera that are seen in the image:
// projected and unprojected, they come back on the normalised plane. Both to 1e-9 relative.
TEST_P(CameraModelTest, RoundTripsOnRandomPoints) {
  const CameraModelId id = GetParam();
  const auto params = ExampleParams(id);
  Random random(17 + static_cast<int>(id));
  VisitCameraModel(id, [&](auto model) {
    using Model = decltype(model);
    for (int i = 0; i < 2000; ++i) {
      const Eigen::Vector2d pixel(random.UniformReal(0.0, kImageWidth),
                                  random.UniformReal(0.0, kImageHeight));
      Eigen::Vector2d uv;
      ASSERT_TRUE(Model::CamFromImgChecked(params.data(), pixel.x(), pixel.y(), &uv))
          << Model::kName << " pixel " << pixel.transpose();
      const double depth = random.UniformReal(0.5, 20.0);
      Eigen::Vector2d back;
      Model::ImgFromCam(params.data(), depth * uv.x(), depth * uv.y(), depth, &back.x(),
                        &back.y());
      EXPECT_LE((back - pixel).norm(), 1e-9 * pixel.norm()) << Model::kName;

      // A point in camera coordinates whose projection is in the image.
      const Eigen::Vector3d point = depth * Eigen::Vector3d(uv.x(), uv.y(), 1.0);
      Eigen::Vector2d projected;
      Model::ImgFromCam(params.data(), point.x(), point.y(), point.z(), &projected.x(),
                        &projected.y());
      const Eigen::Vector2d normalised = Model::CamFromImg(params.data(), projected.x(),
                                                           projected.y());
      const Eigen::Vector2d expected = point.hnormalized();
      EXPECT_LE((normalised - expected).norm(), 1e-9 * std::max(1.0, expected.norm()))
          << Model::kName;
    }
  });
}

TEST_P(CameraModelTest, NameRoundTrips) {
  const CameraModelId id = GetParam();
  EXPECT_EQ(CameraModelFromName(CameraModelName(id)), id);
  EXPECT_EQ(ParseCameraModel(CameraModelName(id)), id);
  EXPECT_TRUE(IsKnownCameraModel(static_cast<int>(id)));
  EXPECT_EQ(static_cast<int>(CameraModelParamNames(id).size()), CameraModelNumParams(id));
}

// Jacobian of ImgFromCam w.r.t. the point (u, v, w) and the parameters, by automatic
// differentiation (what bundle adjustment uses), against central finite differences.
TEST_P(CameraModelTest, ProjectionJacobianMatchesFiniteDifferences) {
  const CameraModelId id = GetParam();
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
  const CameraModelId id = GetParam();
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

INSTANTIATE_TEST_SUITE_P(AllModels, CameraModelTest, ::testing::ValuesIn(kCameraModelIds),
                         [](const auto& info) { return std::string(CameraModelName(info.param)); });

// The ids are COLMAP's (databases and binary models store them), so are the names.
TEST(CameraModels, IdsAndNamesAreColmaps) {
  const std::pair<const char*, int> colmap[] = {
      {"SIMPLE_PINHOLE", 0}, {"PINHOLE", 1},        {"SIMPLE_RADIAL", 2},
      {"RADIAL", 3},         {"OPENCV", 4},         {"OPENCV_FISHEYE", 5},
      {"FULL_OPENCV", 6},    {"SIMPLE_RADIAL_FISHEYE", 8}, {"RADIAL_FISHEYE", 9}};
  for (const auto& [name, id] : colmap) {
    ASSERT_TRUE(CameraModelFromName(name)) << name;
    EXPECT_EQ(static_cast<int>(*CameraModelFromName(name)), id) << name;
  }
  EXPECT_FALSE(IsKnownCameraModel(7));  // COLMAP's FOV
  EXPECT_FALSE(IsKnownCameraModel(10));
  EXPECT_FALSE(IsKnownCameraModel(-1));
  const std::vector<std::string_view> names = CameraModelParamNames(CameraModelId::kFullOpenCV);
  const std::vector<std::string_view> expected = {"fx", "fy", "cx", "cy", "k1", "k2",
                                                  "p1", "p2", "k3", "k4", "k5", "k6"};
  EXPECT_EQ(names, expected);
}

TEST(CameraModels, UnknownNameIsRejectedWithTheValidNames) {
  EXPECT_FALSE(CameraModelFromName("FISHEYE_X"));
  EXPECT_FALSE(CameraModelFromName("opencv"));  // names are case-sensitive, as in COLMAP
  try {
    ParseCameraModel("FOV");
    FAIL();
  } catch (const InvalidArgument& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("unknown camera model 'FOV'"), std::string::npos) << message;
    EXPECT_NE(message.find(CameraModelNameList()), std::string::npos) << message;
  }
  EXPECT_EQ(CameraModelNameList(),
            "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, "
            "FULL_OPENCV, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE");
}

// Beyond the radius where barrel distortion folds over, no undistorted point exists: the
// iteration says so instead of returning a wrong point as if it were right.
TEST(CameraModels, UndistortionFailsOutsideTheInvertibleDomain) {
  // r_d = r (1 + k r^2) with k = -0.15 peaks at r = 1 / sqrt(3 * 0.15), r_d = 0.99381.
  const double k = -0.15;
  const double peak = (1.0 / std::sqrt(-3.0 * k)) * (2.0 / 3.0);
  const double simple_radial[] = {100.0, 0.0, 0.0, k};
  Eigen::Vector2d uv;
  EXPECT_TRUE(SimpleRadialModel::CamFromImgChecked(simple_radial, 0.6 * 100 * peak,
                                                   0.78 * 100 * peak, &uv));
  EXPECT_LT(uv.norm(), 1.0 / std::sqrt(-3.0 * k));  // on the branch before the fold
  EXPECT_FALSE(SimpleRadialModel::CamFromImgChecked(simple_radial, 0.6 * 100 * peak,
                                                    0.81 * 100 * peak, &uv));
  // Equidistant: theta_d = theta (1 + k theta^2) reaches 90 degrees at theta_d = 1.0626.
  const double fisheye[] = {100.0, 0.0, 0.0, -0.05};
  const double theta_d_90 = 0.5 * M_PI * (1.0 - 0.05 * 0.25 * M_PI * M_PI);
  EXPECT_TRUE(SimpleRadialFisheyeModel::CamFromImgChecked(fisheye, 0.0, 99.0 * theta_d_90, &uv));
  EXPECT_NEAR(std::atan(uv.norm()), 0.5 * M_PI, 0.05);
  EXPECT_FALSE(
      SimpleRadialFisheyeModel::CamFromImgChecked(fisheye, 0.0, 101.0 * theta_d_90, &uv));
}

}  // namespace
}  // namespace loopsfm
