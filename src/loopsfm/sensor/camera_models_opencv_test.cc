// Agreement of the camera models with OpenCV: cv::projectPoints / cv::undistortPoints for
// the polynomial and rational models, cv::fisheye::projectPoints / cv::fisheye::undistortPoints
// for the equidistant ones, on random points of the image.

#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <opencv2/calib3d.hpp>

#include "loopsfm/math/random.h"
#include "loopsfm/sensor/camera_models.h"
#include "loopsfm/sensor/camera_models_test_util.h"

namespace loopsfm {
namespace {

using camera_models_test::ExampleParams;
using camera_models_test::kImageHeight;
using camera_models_test::kImageWidth;

constexpr int kNumPoints = 3000;
// OpenCV's undistortPoints stops once its estimate reprojects to within this many pixels.
constexpr double kOpenCVPixelTolerance = 1e-10;
// cv::fisheye::undistortPoints stops once its Newton step on theta is below this (radians).
constexpr double kOpenCVThetaTolerance = 1e-12;

// The same camera in OpenCV's terms: the camera matrix, and the coefficients (k1, k2, p1, p2,
// k3, k4, k5, k6) or, for the equidistant models, cv::fisheye's (k1, k2, k3, k4).
struct OpenCVCamera {
  cv::Matx33d K = cv::Matx33d::eye();
  std::vector<double> coefficients;
  bool fisheye = false;
};

OpenCVCamera ToOpenCV(CameraModelId id, const std::vector<double>& params) {
  OpenCVCamera camera;
  camera.fisheye = CameraModelName(id).ends_with("FISHEYE");
  const std::vector<std::string> order =
      camera.fisheye ? std::vector<std::string>{"k1", "k2", "k3", "k4"}
                     : std::vector<std::string>{"k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"};
  camera.coefficients.assign(order.size(), 0.0);
  const std::vector<std::string_view> names = CameraModelParamNames(id);
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string name(names[i]);
    if (name == "f") {
      camera.K(0, 0) = camera.K(1, 1) = params[i];
    } else if (name == "fx") {
      camera.K(0, 0) = params[i];
    } else if (name == "fy") {
      camera.K(1, 1) = params[i];
    } else if (name == "cx") {
      camera.K(0, 2) = params[i];
    } else if (name == "cy") {
      camera.K(1, 2) = params[i];
    } else {
      const std::string coefficient = name == "k" ? "k1" : name;
      const auto it = std::find(order.begin(), order.end(), coefficient);
      EXPECT_NE(it, order.end()) << name;
      camera.coefficients[it - order.begin()] = params[i];
    }
  }
  return camera;
}

// Random points of the image (pixels) and, through the model, points in front of the camera
// that project onto them.
void RandomPoints(CameraModelId id, const std::vector<double>& params,
                  std::vector<cv::Point2d>* pixels, std::vector<cv::Point3d>* points) {
  Random random(101 + static_cast<int>(id));
  for (int i = 0; i < kNumPoints; ++i) {
    const Eigen::Vector2d pixel(random.UniformReal(0.0, kImageWidth),
                                random.UniformReal(0.0, kImageHeight));
    const Eigen::Vector2d uv = VisitCameraModel(id, [&](auto model) {
      return decltype(model)::CamFromImg(params.data(), pixel.x(), pixel.y());
    });
    const double depth = random.UniformReal(0.5, 20.0);
    pixels->emplace_back(pixel.x(), pixel.y());
    points->emplace_back(depth * uv.x(), depth * uv.y(), depth);
  }
}

Eigen::Vector2d Project(CameraModelId id, const std::vector<double>& params,
                        const Eigen::Vector3d& point) {
  return VisitCameraModel(id, [&](auto model) {
    Eigen::Vector2d xy;
    decltype(model)::ImgFromCam(params.data(), point.x(), point.y(), point.z(), &xy.x(), &xy.y());
    return xy;
  });
}

// Largest singular value of the inverse of d pixel / d (u, v) at normalised point uv: how much
// a pixel residual moves the undistorted point.
double InverseJacobianNorm(CameraModelId id, const std::vector<double>& params,
                           const Eigen::Vector2d& uv) {
  Eigen::Matrix2d jacobian;
  const double h = 1e-6 * std::max(1.0, uv.norm());
  for (int k = 0; k < 2; ++k) {
    Eigen::Vector2d d = Eigen::Vector2d::Zero();
    d[k] = h;
    jacobian.col(k) = (Project(id, params, (uv + d).homogeneous()) -
                       Project(id, params, (uv - d).homogeneous())) / (2 * h);
  }
  return 1.0 / Eigen::JacobiSVD<Eigen::Matrix2d>(jacobian).singularValues()(1);
}

// The example camera of the model, in OpenCV's terms too, and random points of its image.
class CameraModelOpenCVTest : public ::testing::TestWithParam<CameraModelId> {
 protected:
  void SetUp() override {
    id = GetParam();
    params = ExampleParams(id);
    cv_camera = ToOpenCV(id, params);
    RandomPoints(id, params, &pixels, &points);
  }
  CameraModelId id{};
  std::vector<double> params;
  OpenCVCamera cv_camera;
  std::vector<cv::Point2d> pixels;
  std::vector<cv::Point3d> points;
};

// Projection is a closed form on both sides; they differ only in the order of the floating
// point operations (a few units in the last place of each term, or one more rounding where
// -march=native contracts a product and a sum into an FMA). 1e-12 of the largest term,
// f (1 + r_d) + |c|, is thousands of times that and well below any use.
TEST_P(CameraModelOpenCVTest, ProjectionMatchesOpenCV) {
  std::vector<cv::Point2d> projected;
  const cv::Vec3d zero(0, 0, 0);
  if (cv_camera.fisheye) {
    cv::fisheye::projectPoints(points, projected, zero, zero, cv_camera.K,
                               cv_camera.coefficients);
  } else {
    cv::projectPoints(points, zero, zero, cv_camera.K, cv_camera.coefficients, projected);
  }
  ASSERT_EQ(projected.size(), points.size());
  const double focal = std::max(cv_camera.K(0, 0), cv_camera.K(1, 1));
  const double principal = std::max(cv_camera.K(0, 2), cv_camera.K(1, 2));
  double max_difference = 0.0;
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector2d ours =
        Project(id, params, Eigen::Vector3d(points[i].x, points[i].y, points[i].z));
    const Eigen::Vector2d theirs(projected[i].x, projected[i].y);
    const double r_d = (ours - Eigen::Vector2d(cv_camera.K(0, 2), cv_camera.K(1, 2))).norm() /
                       std::min(cv_camera.K(0, 0), cv_camera.K(1, 1));
    const double difference = (ours - theirs).norm();
    max_difference = std::max(max_difference, difference);
    EXPECT_LE(difference, 1e-12 * (focal * (1.0 + r_d) + principal))
        << CameraModelName(id) << " point " << i;
    // The random points were made by our unprojection of a pixel: OpenCV projects them back.
    EXPECT_LE((theirs - Eigen::Vector2d(pixels[i].x, pixels[i].y)).norm(), 1e-9 * kImageWidth);
  }
  std::cout << "[ measured ] " << CameraModelName(id) << ": projection differs from OpenCV's by "
            << max_difference << " px at most\n";
}

// Undistortion iterates on both sides, so they agree to within their stopping tolerances, each
// carried to the undistorted point by the local inverse Jacobian:
//   polynomial and rational models: OpenCV stops within kOpenCVPixelTolerance pixels, we
//     within kUndistortionTolerance * max(1, |x_d|) on the normalised plane (times the focal
//     length in pixels); both errors times |d pixel / d (u, v)|^-1;
//   equidistant models: OpenCV's theta is within its last Newton step (kOpenCVThetaTolerance),
//     ours within kUndistortionTolerance * max(1, theta_d) / (d theta_d / d theta); r = tan
//     theta turns an error in theta into one (1 + r^2) times larger.
// A factor 2 covers the linearisation; 1e-14 * max(1, |uv|) the rounding of the final scaling.
TEST_P(CameraModelOpenCVTest, UnprojectionMatchesOpenCV) {
  std::vector<cv::Point2d> undistorted;
  if (cv_camera.fisheye) {
    cv::fisheye::undistortPoints(
        pixels, undistorted, cv_camera.K, cv_camera.coefficients, cv::noArray(), cv::noArray(),
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100,
                         kOpenCVThetaTolerance));
  } else {
    cv::undistortPoints(pixels, undistorted, cv_camera.K, cv_camera.coefficients, cv::noArray(),
                        cv::noArray(),
                        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 1000,
                                         kOpenCVPixelTolerance));
  }
  ASSERT_EQ(undistorted.size(), pixels.size());
  const double focal = std::max(cv_camera.K(0, 0), cv_camera.K(1, 1));
  double max_difference = 0.0, max_ratio = 0.0;
  for (size_t i = 0; i < pixels.size(); ++i) {
    const Eigen::Vector2d ours = Eigen::Vector3d(points[i].x, points[i].y, points[i].z).hnormalized();
    const Eigen::Vector2d theirs(undistorted[i].x, undistorted[i].y);
    double bound = 0.0;
    if (cv_camera.fisheye) {
      const double r = ours.norm();
      const double theta = std::atan(r);
      const Eigen::Vector2d distorted(
          (pixels[i].x - cv_camera.K(0, 2)) / cv_camera.K(0, 0),
          (pixels[i].y - cv_camera.K(1, 2)) / cv_camera.K(1, 1));
      const double h = 1e-6;
      auto theta_d = [&](double t) {
        return t * (1.0 + t * t * (cv_camera.coefficients[0] +
                                   t * t * (cv_camera.coefficients[1] +
                                            t * t * (cv_camera.coefficients[2] +
                                                     t * t * cv_camera.coefficients[3]))));
      };
      const double derivative = (theta_d(theta + h) - theta_d(theta - h)) / (2 * h);
      const double our_theta_error =
          kUndistortionTolerance * std::max(1.0, distorted.norm()) / derivative;
      bound = (1.0 + r * r) * (kOpenCVThetaTolerance + our_theta_error);
    } else {
      const Eigen::Vector2d distorted =
          (Project(id, params, ours.homogeneous()) - Eigen::Vector2d(cv_camera.K(0, 2), cv_camera.K(1, 2))) / focal;
      const double our_pixel_residual =
          focal * kUndistortionTolerance * std::max(1.0, distorted.norm());
      bound = InverseJacobianNorm(id, params, ours) * (kOpenCVPixelTolerance + our_pixel_residual);
    }
    const double tolerance = 2.0 * bound + 1e-14 * std::max(1.0, ours.norm());
    const double difference = (ours - theirs).norm();
    max_difference = std::max(max_difference, difference);
    max_ratio = std::max(max_ratio, difference / tolerance);
    EXPECT_LE(difference, tolerance) << CameraModelName(id) << " pixel (" << pixels[i].x << ", "
                                     << pixels[i].y << ")";
  }
  std::cout << "[ measured ] " << CameraModelName(id)
            << ": undistortion differs from OpenCV's by " << max_difference
            << " (normalised) at most, " << max_ratio << " of the tolerance\n";
}

INSTANTIATE_TEST_SUITE_P(AllModels, CameraModelOpenCVTest, ::testing::ValuesIn(kCameraModelIds),
                         [](const auto& info) { return std::string(CameraModelName(info.param)); });

}  // namespace
}  // namespace loopsfm
