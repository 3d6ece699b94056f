#pragma once
// Camera models as static structs with COLMAP's ids, names and parameter orders, so
// models round-trip through COLMAP databases and model files unchanged.
//
// Image coordinates follow COLMAP: the centre of the top-left pixel is (0.5, 0.5).
// Every model provides, templated for Ceres' automatic differentiation:
//   ImgFromCam(params, u, v, w, &x, &y)   project a point in camera coordinates
//   Distortion(extra, u, v, &du, &dv)     additive distortion of normalised coordinates
// and CamFromImg (unprojection to the normalised plane, undistortion by iteration).

#include <array>
#include <cmath>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include <Eigen/Core>
#include <Eigen/LU>

namespace loopsfm {

enum class CameraModelId : int {
  kSimplePinhole = 0,
  kPinhole = 1,
  kSimpleRadial = 2,
  kRadial = 3,
  kOpenCV = 4,
};

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

  // Normalised image-plane coordinates (z = 1) of pixel (x, y).
  static Eigen::Vector2d CamFromImg(const double* params, double x, double y) {
    double u, v;
    if constexpr (Derived::kNumFocal == 1) {
      u = (x - params[1]) / params[0];
      v = (y - params[2]) / params[0];
    } else {
      u = (x - params[2]) / params[0];
      v = (y - params[3]) / params[1];
    }
    if constexpr (Derived::kNumParams > Derived::kNumFocalAndPP) Undistort(params, &u, &v);
    return {u, v};
  }

  // Solves undistorted + distortion(undistorted) = distorted by Newton's method with a
  // numerical Jacobian (the distortion is smooth and close to identity in practice).
  static void Undistort(const double* params, double* u, double* v) {
    const double* extra = params + Derived::kNumFocalAndPP;
    const Eigen::Vector2d target(*u, *v);
    Eigen::Vector2d x = target;
    for (int iter = 0; iter < 100; ++iter) {
      auto f = [&](const Eigen::Vector2d& p) {
        double du, dv;
        Derived::Distortion(extra, p.x(), p.y(), &du, &dv);
        return Eigen::Vector2d(p.x() + du, p.y() + dv);
      };
      const Eigen::Vector2d r = f(x) - target;
      if (r.squaredNorm() < 1e-24) break;
      const double h = 1e-9 * std::max(1.0, x.norm());
      Eigen::Matrix2d J;
      J.col(0) = (f(x + Eigen::Vector2d(h, 0)) - f(x - Eigen::Vector2d(h, 0))) / (2 * h);
      J.col(1) = (f(x + Eigen::Vector2d(0, h)) - f(x - Eigen::Vector2d(0, h))) / (2 * h);
      const Eigen::Vector2d step = J.inverse() * r;
      x -= step;
      if (step.squaredNorm() < 1e-28) break;
    }
    *u = x.x();
    *v = x.y();
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

// Calls f(Model{}) with the static model struct of a runtime id.
template <typename F>
decltype(auto) VisitCameraModel(CameraModelId id, F&& f) {
  switch (id) {
    case CameraModelId::kSimplePinhole: return f(SimplePinholeModel{});
    case CameraModelId::kPinhole: return f(PinholeModel{});
    case CameraModelId::kSimpleRadial: return f(SimpleRadialModel{});
    case CameraModelId::kRadial: return f(RadialModel{});
    case CameraModelId::kOpenCV: return f(OpenCVModel{});
  }
  return f(PinholeModel{});
}

inline bool IsKnownCameraModel(int id) { return id >= 0 && id <= 4; }
std::string_view CameraModelName(CameraModelId id);
int CameraModelNumParams(CameraModelId id);
// Parses a COLMAP model name ("PINHOLE", "OPENCV", ...); nullopt when unknown.
std::optional<CameraModelId> CameraModelFromName(std::string_view name);

}  // namespace loopsfm
