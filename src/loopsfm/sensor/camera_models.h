#pragma once
// Camera models as static structs with COLMAP's ids, names and parameter orders, so
// models round-trip through COLMAP databases and model files unchanged.
//
// Image coordinates follow COLMAP: the centre of the top-left pixel is (0.5, 0.5).
// Every model provides, templated for Ceres' automatic differentiation:
//   ImgFromCam(params, u, v, w, &x, &y)   project a point in camera coordinates
//   Distortion(extra, u, v, &du, &dv)     additive distortion of normalised coordinates
// and CamFromImg (unprojection to the normalised plane, undistortion by Newton's method).
//
// The fisheye models are equidistant (OpenCV's cv::fisheye, COLMAP's *_FISHEYE): a ray at
// angle theta from the optical axis lands at radius theta_d = theta (1 + k1 theta^2 + ...) on
// the normalised plane. As in COLMAP, they work on the normalised plane z = 1, so they cover
// rays less than 90 degrees from the axis.

#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>

namespace loopsfm {

// COLMAP's model ids (stored in databases and binary models). COLMAP's FOV (7) and the
// thin-prism models (10, 11) are not supported.
enum class CameraModelId : int {
  kSimplePinhole = 0,
  kPinhole = 1,
  kSimpleRadial = 2,
  kRadial = 3,
  kOpenCV = 4,
  kOpenCVFisheye = 5,
  kFullOpenCV = 6,
  kSimpleRadialFisheye = 8,
  kRadialFisheye = 9,
};

// Every supported model, in id order.
inline constexpr std::array<CameraModelId, 9> kCameraModelIds = {
    CameraModelId::kSimplePinhole, CameraModelId::kPinhole,
    CameraModelId::kSimpleRadial,  CameraModelId::kRadial,
    CameraModelId::kOpenCV,        CameraModelId::kOpenCVFisheye,
    CameraModelId::kFullOpenCV,    CameraModelId::kSimpleRadialFisheye,
    CameraModelId::kRadialFisheye,
};

// Undistortion (CamFromImg) iterates until the distortion of its estimate matches the
// distorted point to within this fraction of max(1, |distorted point|) on the normalised
// plane (about 45 units in the last place of a double); the error of the undistorted point
// is then at most this residual times the norm of the inverse Jacobian of the distortion.
inline constexpr double kUndistortionTolerance = 1e-14;
inline constexpr int kUndistortionMaxIterations = 100;

// Shared projection code: focal(s) and principal point, then a model-specific distortion.
template <typename Derived>
struct BaseCameraModel {
  template <typename T>
  static void ImgFromCam(const T* params, T u, T v, T w, T* x, T* y) {
    u /= w;
    v /= w;
    T du, dv;
    Derived::Distortion(params + Derived::kNumFocalAndPP, u, v, &du, &dv);
    u += du;
    v += dv;
    if constexpr (Derived::kNumFocal == 1) {
      *x = params[0] * u + params[1];
      *y = params[0] * v + params[2];
    } else {
      *x = params[0] * u + params[2];
      *y = params[1] * v + params[3];
    }
  }

  // Normalised image-plane coordinates (z = 1) of pixel (x, y). Where the undistortion does
  // not converge (a pixel outside the image of the model's invertible domain), the last
  // iterate is returned; CamFromImgChecked tells.
  static Eigen::Vector2d CamFromImg(const double* params, double x, double y) {
    Eigen::Vector2d uv;
    CamFromImgChecked(params, x, y, &uv);
    return uv;
  }

  // CamFromImg; false where the undistortion did not converge.
  static bool CamFromImgChecked(const double* params, double x, double y, Eigen::Vector2d* uv) {
    if constexpr (Derived::kNumFocal == 1) {
      uv->x() = (x - params[1]) / params[0];
      uv->y() = (y - params[2]) / params[0];
    } else {
      uv->x() = (x - params[2]) / params[0];
      uv->y() = (y - params[3]) / params[1];
    }
    if constexpr (Derived::kNumParams > Derived::kNumFocalAndPP) {
      return Derived::Undistort(params + Derived::kNumFocalAndPP, &uv->x(), &uv->y());
    }
    return true;
  }

  // Solves undistorted + Distortion(undistorted) = distorted (in place) by Newton's method,
  // starting from the distorted point, with a central-difference Jacobian (as COLMAP does).
  // True once the residual is within kUndistortionTolerance at a point where the distortion
  // keeps its orientation (Jacobian determinant > 0) and the side of the axis; false when
  // the iteration does not converge there (beyond the radius where the lens folds over).
  static bool Undistort(const double* extra, double* u, double* v) {
    const Eigen::Vector2d target(*u, *v);
    const double tolerance = kUndistortionTolerance * std::max(1.0, target.norm());
    auto distort = [extra](const Eigen::Vector2d& p) {
      double du, dv;
      Derived::Distortion(extra, p.x(), p.y(), &du, &dv);
      return Eigen::Vector2d(p.x() + du, p.y() + dv);
    };
    Eigen::Vector2d x = target;
    bool converged = false;
    for (int iter = 0; iter < kUndistortionMaxIterations; ++iter) {
      const Eigen::Vector2d residual = distort(x) - target;
      // A relative step of 1e-6 balances truncation (h^2) and rounding (eps / h) errors.
      const double h = 1e-6 * std::max(1.0, x.norm());
      const Eigen::Vector2d hx(h, 0.0), hy(0.0, h);
      Eigen::Matrix2d jacobian;
      jacobian.col(0) = (distort(x + hx) - distort(x - hx)) / (2.0 * h);
      jacobian.col(1) = (distort(x + hy) - distort(x - hy)) / (2.0 * h);
      const double det = jacobian.determinant();
      if (!residual.allFinite() || !(det > 1e-12 * jacobian.squaredNorm())) break;
      if (residual.norm() <= tolerance) {
        converged = x.dot(target) >= 0.0;
        break;
      }
      x -= jacobian.inverse() * residual;
    }
    *u = x.x();
    *v = x.y();
    return converged;
  }
};

// theta_d = theta (1 + k[0] theta^2 + k[1] theta^4 + ... + k[N-1] theta^(2N)), the radius on
// the normalised plane of a ray at angle theta from the axis, for the equidistant models.
template <int N, typename T>
T FisheyeThetaD(const T* k, const T& theta) {
  const T theta2 = theta * theta;
  T poly = k[N - 1];
  for (int i = N - 2; i >= 0; --i) poly = k[i] + theta2 * poly;
  return theta * (T(1) + theta2 * poly);
}

// Equidistant fisheye distortion with N coefficients as an additive term (COLMAP's form).
template <int N, typename T>
void FisheyeDistortion(const T* k, T u, T v, T* du, T* dv) {
  using std::atan;
  using std::sqrt;
  const T r2 = u * u + v * v;
  // At r = 0 the distortion is zero; sqrt would have an infinite derivative there.
  constexpr double kEps = std::numeric_limits<double>::epsilon();
  if (r2 > T(kEps * kEps)) {
    const T r = sqrt(r2);
    const T scale = FisheyeThetaD<N>(k, atan(r)) / r - T(1);
    *du = u * scale;
    *dv = v * scale;
  } else {
    *du = T(0);
    *dv = T(0);
  }
}

// Inverts the equidistant distortion in place: Newton's method on theta (as OpenCV's
// cv::fisheye::undistortPoints), from theta = theta_d, until theta_d(theta) matches to within
// kUndistortionTolerance * max(1, theta_d); then r = tan(theta). False where the iteration
// does not converge, the model folds over (d theta_d / d theta <= 0) or theta reaches 90
// degrees (no ray in front of the camera).
template <int N>
bool FisheyeUndistort(const double* k, double* u, double* v) {
  const double theta_d = std::hypot(*u, *v);
  if (theta_d == 0.0) return true;
  const double tolerance = kUndistortionTolerance * std::max(1.0, theta_d);
  double theta = theta_d;
  bool converged = false;
  for (int iter = 0; iter < kUndistortionMaxIterations; ++iter) {
    const double residual = FisheyeThetaD<N>(k, theta) - theta_d;
    // d theta_d / d theta = 1 + 3 k[0] theta^2 + 5 k[1] theta^4 + ...
    const double theta2 = theta * theta;
    double derivative = (2 * N + 1) * k[N - 1];
    for (int i = N - 2; i >= 0; --i) derivative = (2 * i + 3) * k[i] + theta2 * derivative;
    derivative = 1.0 + theta2 * derivative;
    if (!(derivative > 0.0)) break;
    if (std::abs(residual) <= tolerance) {
      converged = true;
      break;
    }
    theta -= residual / derivative;
  }
  if (!converged || !(theta > 0.0 && theta < 0.5 * std::numbers::pi)) return false;
  const double scale = std::tan(theta) / theta_d;
  *u *= scale;
  *v *= scale;
  return true;
}

// The equidistant models with N coefficients: FisheyeDistortion and FisheyeUndistort.
template <typename Derived, int N>
struct EquidistantCameraModel : BaseCameraModel<Derived> {
  template <typename T>
  static void Distortion(const T* extra, T u, T v, T* du, T* dv) {
    FisheyeDistortion<N>(extra, u, v, du, dv);
  }
  static bool Undistort(const double* extra, double* u, double* v) {
    return FisheyeUndistort<N>(extra, u, v);
  }
};

struct SimplePinholeModel : BaseCameraModel<SimplePinholeModel> {
  static constexpr CameraModelId kId = CameraModelId::kSimplePinhole;
  static constexpr std::string_view kName = "SIMPLE_PINHOLE";
  static constexpr int kNumParams = 3, kNumFocal = 1, kNumFocalAndPP = 3;
  static constexpr std::string_view kParamsInfo = "f, cx, cy";
  template <typename T>
  static void Distortion(const T*, T, T, T* du, T* dv) { *du = T(0); *dv = T(0); }
};

struct PinholeModel : BaseCameraModel<PinholeModel> {
  static constexpr CameraModelId kId = CameraModelId::kPinhole;
  static constexpr std::string_view kName = "PINHOLE";
  static constexpr int kNumParams = 4, kNumFocal = 2, kNumFocalAndPP = 4;
  static constexpr std::string_view kParamsInfo = "fx, fy, cx, cy";
  template <typename T>
  static void Distortion(const T*, T, T, T* du, T* dv) { *du = T(0); *dv = T(0); }
};

struct SimpleRadialModel : BaseCameraModel<SimpleRadialModel> {
  static constexpr CameraModelId kId = CameraModelId::kSimpleRadial;
  static constexpr std::string_view kName = "SIMPLE_RADIAL";
  static constexpr int kNumParams = 4, kNumFocal = 1, kNumFocalAndPP = 3;
  static constexpr std::string_view kParamsInfo = "f, cx, cy, k";
  template <typename T>
  static void Distortion(const T* extra, T u, T v, T* du, T* dv) {
    const T radial = extra[0] * (u * u + v * v);
    *du = u * radial;
    *dv = v * radial;
  }
};

struct RadialModel : BaseCameraModel<RadialModel> {
  static constexpr CameraModelId kId = CameraModelId::kRadial;
  static constexpr std::string_view kName = "RADIAL";
  static constexpr int kNumParams = 5, kNumFocal = 1, kNumFocalAndPP = 3;
  static constexpr std::string_view kParamsInfo = "f, cx, cy, k1, k2";
  template <typename T>
  static void Distortion(const T* extra, T u, T v, T* du, T* dv) {
    const T r2 = u * u + v * v;
    const T radial = extra[0] * r2 + extra[1] * r2 * r2;
    *du = u * radial;
    *dv = v * radial;
  }
};

struct OpenCVModel : BaseCameraModel<OpenCVModel> {
  static constexpr CameraModelId kId = CameraModelId::kOpenCV;
  static constexpr std::string_view kName = "OPENCV";
  static constexpr int kNumParams = 8, kNumFocal = 2, kNumFocalAndPP = 4;
  static constexpr std::string_view kParamsInfo = "fx, fy, cx, cy, k1, k2, p1, p2";
  template <typename T>
  static void Distortion(const T* extra, T u, T v, T* du, T* dv) {
    const T k1 = extra[0], k2 = extra[1], p1 = extra[2], p2 = extra[3];
    const T u2 = u * u, v2 = v * v, uv = u * v, r2 = u2 + v2;
    const T radial = k1 * r2 + k2 * r2 * r2;
    *du = u * radial + T(2) * p1 * uv + p2 * (r2 + T(2) * u2);
    *dv = v * radial + T(2) * p2 * uv + p1 * (r2 + T(2) * v2);
  }
};

// Equidistant fisheye with four coefficients (OpenCV's cv::fisheye model).
struct OpenCVFisheyeModel : EquidistantCameraModel<OpenCVFisheyeModel, 4> {
  static constexpr CameraModelId kId = CameraModelId::kOpenCVFisheye;
  static constexpr std::string_view kName = "OPENCV_FISHEYE";
  static constexpr int kNumParams = 8, kNumFocal = 2, kNumFocalAndPP = 4;
  static constexpr std::string_view kParamsInfo = "fx, fy, cx, cy, k1, k2, k3, k4";
};

// OpenCV's rational model (cv::projectPoints with 8 coefficients, in the same order).
struct FullOpenCVModel : BaseCameraModel<FullOpenCVModel> {
  static constexpr CameraModelId kId = CameraModelId::kFullOpenCV;
  static constexpr std::string_view kName = "FULL_OPENCV";
  static constexpr int kNumParams = 12, kNumFocal = 2, kNumFocalAndPP = 4;
  static constexpr std::string_view kParamsInfo =
      "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6";
  template <typename T>
  static void Distortion(const T* extra, T u, T v, T* du, T* dv) {
    const T k1 = extra[0], k2 = extra[1], p1 = extra[2], p2 = extra[3];
    const T k3 = extra[4], k4 = extra[5], k5 = extra[6], k6 = extra[7];
    const T u2 = u * u, v2 = v * v, uv = u * v, r2 = u2 + v2;
    const T r4 = r2 * r2, r6 = r4 * r2;
    const T radial = (T(1) + k1 * r2 + k2 * r4 + k3 * r6) / (T(1) + k4 * r2 + k5 * r4 + k6 * r6);
    *du = u * radial + T(2) * p1 * uv + p2 * (r2 + T(2) * u2) - u;
    *dv = v * radial + T(2) * p2 * uv + p1 * (r2 + T(2) * v2) - v;
  }
};

struct SimpleRadialFisheyeModel : EquidistantCameraModel<SimpleRadialFisheyeModel, 1> {
  static constexpr CameraModelId kId = CameraModelId::kSimpleRadialFisheye;
  static constexpr std::string_view kName = "SIMPLE_RADIAL_FISHEYE";
  static constexpr int kNumParams = 4, kNumFocal = 1, kNumFocalAndPP = 3;
  static constexpr std::string_view kParamsInfo = "f, cx, cy, k";
};

struct RadialFisheyeModel : EquidistantCameraModel<RadialFisheyeModel, 2> {
  static constexpr CameraModelId kId = CameraModelId::kRadialFisheye;
  static constexpr std::string_view kName = "RADIAL_FISHEYE";
  static constexpr int kNumParams = 5, kNumFocal = 1, kNumFocalAndPP = 3;
  static constexpr std::string_view kParamsInfo = "f, cx, cy, k1, k2";
};

// Calls f(Model{}) with the static model struct of a runtime id.
template <typename F>
decltype(auto) VisitCameraModel(CameraModelId id, F&& f) {
  switch (id) {
    case CameraModelId::kSimplePinhole: return f(SimplePinholeModel{});
    case CameraModelId::kPinhole: return f(PinholeModel{});
    case CameraModelId::kSimpleRadial: return f(SimpleRadialModel{});
    case CameraModelId::kRadial: return f(RadialModel{});
    case CameraModelId::kOpenCV: return f(OpenCVModel{});
    case CameraModelId::kOpenCVFisheye: return f(OpenCVFisheyeModel{});
    case CameraModelId::kFullOpenCV: return f(FullOpenCVModel{});
    case CameraModelId::kSimpleRadialFisheye: return f(SimpleRadialFisheyeModel{});
    case CameraModelId::kRadialFisheye: return f(RadialFisheyeModel{});
  }
  return f(PinholeModel{});
}

// True for the COLMAP model ids in kCameraModelIds.
bool IsKnownCameraModel(int id);
std::string_view CameraModelName(CameraModelId id);
int CameraModelNumParams(CameraModelId id);
// The model's kParamsInfo: "fx, fy, cx, cy, k1, k2, p1, p2" for OPENCV.
std::string_view CameraModelParamsInfo(CameraModelId id);
// The names of the model's parameters in order, from kParamsInfo ("fx", "fy", "cx", ...).
std::vector<std::string_view> CameraModelParamNames(CameraModelId id);
// "SIMPLE_PINHOLE, PINHOLE, ..., RADIAL_FISHEYE": the supported names, for messages.
std::string CameraModelNameList();
// Parses a COLMAP model name ("PINHOLE", "OPENCV", ...); nullopt when unknown.
std::optional<CameraModelId> CameraModelFromName(std::string_view name);
// CameraModelFromName; throws InvalidArgument listing the supported names when unknown.
CameraModelId ParseCameraModel(std::string_view name);

}  // namespace loopsfm
