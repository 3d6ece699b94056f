#include "loopsfm/matching/geometric_verification.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <vector>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "loopsfm/matching/relative_pose_refinement.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// One robustly estimated 3x3 model and its inlier mask over the raw matches.
struct ModelEstimate {
  Eigen::Matrix3d model = Eigen::Matrix3d::Zero();
  std::vector<char> inliers;
  int num_inliers = 0;
};

cv::UsacParams MakeUsacParams(const TwoViewVerificationOptions& options, double threshold,
                              int seed) {
  cv::UsacParams params;
  params.confidence = options.confidence;
  params.isParallel = false;
  params.loMethod = cv::LOCAL_OPTIM_INNER_LO;
  params.maxIterations = options.max_num_trials;
  params.randomGeneratorState = seed;
  params.sampler = cv::SAMPLING_UNIFORM;
  params.score = cv::SCORE_METHOD_MSAC;
  params.threshold = threshold;
  return params;
}

// Runs an OpenCV estimator `estimate(mask) -> cv::Mat`; a failure (no model, or an OpenCV
// exception on degenerate input) gives an estimate with no inliers.
template <typename Estimator>
ModelEstimate RunEstimator(size_t num_points, Estimator&& estimate) {
  ModelEstimate result;
  cv::Mat mask, model;
  try {
    model = estimate(mask);
  } catch (const cv::Exception&) {
    return result;
  }
  if (model.empty() || model.cols != 3 || model.rows < 3 || mask.total() != num_points) {
    return result;
  }
  model.convertTo(model, CV_64F);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) result.model(r, c) = model.at<double>(r, c);
  }
  const cv::Mat mask8 = mask.reshape(1, static_cast<int>(num_points));
  result.inliers.resize(num_points);
  for (size_t i = 0; i < num_points; ++i) {
    result.inliers[i] = mask8.at<uchar>(static_cast<int>(i)) != 0;
    result.num_inliers += result.inliers[i];
  }
  return result;
}

// The pinhole part of a camera's intrinsics (focal lengths and principal point).
Eigen::Matrix3d CalibrationMatrix(const Camera& camera) {
  return VisitCameraModel(camera.model_id, [&](auto model) {
    using Model = decltype(model);
    const double* p = camera.params.data();
    Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
    if constexpr (Model::kNumFocal == 1) {
      K(0, 0) = K(1, 1) = p[0];
      K(0, 2) = p[1];
      K(1, 2) = p[2];
    } else {
      K(0, 0) = p[0];
      K(1, 1) = p[1];
      K(0, 2) = p[2];
      K(1, 2) = p[3];
    }
    return K;
  });
}

cv::Mat ToCv(const Eigen::Matrix3d& m) {
  cv::Mat out(3, 3, CV_64F);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out.at<double>(r, c) = m(r, c);
  }
  return out;
}

Eigen::Matrix3d ToEigen3(const cv::Mat& m) {
  Eigen::Matrix3d out;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out(r, c) = m.at<double>(r, c);
  }
  return out;
}

// Cheirality and ray angles of matches of normalised points under cam2_from_cam1: a match
// counts when the midpoint of its two rays lies in front of both cameras. The angle is between
// ray 1 and ray 2 rotated into camera 1 (the triangulation angle when the rays meet).
struct PoseSupport {
  int num_in_front = 0;
  double median_angle_deg = 0.0;
};

// Without with_angle, only num_in_front is computed.
PoseSupport EvaluatePose(const Rigid3d& cam2_from_cam1,
                         const std::vector<Eigen::Vector2d>& points1,
                         const std::vector<Eigen::Vector2d>& points2, bool with_angle = true) {
  PoseSupport support;
  const Eigen::Matrix3d Rt = cam2_from_cam1.rotation.toRotationMatrix().transpose();
  const Eigen::Vector3d center2 = -Rt * cam2_from_cam1.translation;
  std::vector<double> angles;
  if (with_angle) angles.reserve(points1.size());
  for (size_t i = 0; i < points1.size(); ++i) {
    const Eigen::Vector3d d1 = points1[i].homogeneous();
    const Eigen::Vector3d d2 = Rt * points2[i].homogeneous();
    const double a = d1.dot(d1), b = d1.dot(d2), c = d2.dot(d2);
    if (with_angle) angles.push_back(std::acos(std::clamp(b / std::sqrt(a * c), -1.0, 1.0)));
    const double det = a * c - b * b;
    if (det <= 1e-12 * a * c) continue;
    const double e = d1.dot(center2), f = d2.dot(center2);
    const double depth1 = (c * e - b * f) / det;
    const double depth2 = (b * e - a * f) / det;
    if (depth1 > 0 && depth2 > 0) ++support.num_in_front;
  }
  if (!angles.empty()) {
    auto mid = angles.begin() + angles.size() / 2;
    std::nth_element(angles.begin(), mid, angles.end());
    support.median_angle_deg = *mid * 180.0 / M_PI;
  }
  return support;
}

Rigid3d MakeRigid(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  return Rigid3d(Eigen::Quaterniond(R).normalized(), t);
}

// Relative pose from an essential matrix: of the four decompositions (R = U W V^T or
// U W^T V^T, t = ±u3), the one with the most matches in front of both cameras. (OpenCV's
// recoverPose does the same but triangulates every match by an SVD per point for each
// candidate, which made it the most expensive step of verifying a good pair.)
Rigid3d PoseFromEssential(const Eigen::Matrix3d& E, const std::vector<Eigen::Vector2d>& points1,
                          const std::vector<Eigen::Vector2d>& points2) {
  if (!E.allFinite() || E.norm() < 1e-12) return Rigid3d();  // identity, zero translation
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(E, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  if (U.determinant() < 0) U = -U;
  if (V.determinant() < 0) V = -V;
  Eigen::Matrix3d W;
  W << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const Eigen::Matrix3d rotations[2] = {U * W * V.transpose(), U * W.transpose() * V.transpose()};
  const Eigen::Vector3d t = U.col(2);
  Rigid3d best;
  int best_support = -1;
  for (const Eigen::Matrix3d& R : rotations) {
    for (const double sign : {1.0, -1.0}) {
      const Rigid3d pose = MakeRigid(R, sign * t);
      const int support = EvaluatePose(pose, points1, points2, /*with_angle=*/false).num_in_front;
      if (support > best_support) {
        best_support = support;
        best = pose;
      }
    }
  }
  return best;
}

// The entries of `points` where mask is set.
std::vector<Eigen::Vector2d> Select(const std::vector<Eigen::Vector2d>& points,
                                    const std::vector<char>& mask) {
  std::vector<Eigen::Vector2d> selected;
  for (size_t i = 0; i < points.size(); ++i) {
    if (mask[i]) selected.push_back(points[i]);
  }
  return selected;
}

// Sampson inliers of a fundamental or essential matrix.
int SelectInliers(const Eigen::Matrix3d& M, const std::vector<Eigen::Vector2d>& points1,
                  const std::vector<Eigen::Vector2d>& points2, double threshold,
                  std::vector<char>* mask) {
  mask->assign(points1.size(), 0);
  int count = 0;
  for (size_t i = 0; i < points1.size(); ++i) {
    (*mask)[i] = SampsonSquaredError(M, points1[i], points2[i]) < threshold * threshold;
    count += (*mask)[i];
  }
  return count;
}

// The pose of E, polished on the inliers of *mask (normalised points). With reselect, the
// inliers are then re-selected by Sampson error under the polished E and the pose polished
// again (at most twice), which is what makes E's inlier count comparable to F's.
Rigid3d PolishPose(const Eigen::Matrix3d& E, const std::vector<Eigen::Vector2d>& points1,
                   const std::vector<Eigen::Vector2d>& points2, double threshold, bool reselect,
                   std::vector<char>* mask) {
  std::vector<Eigen::Vector2d> inliers1 = Select(points1, *mask);
  std::vector<Eigen::Vector2d> inliers2 = Select(points2, *mask);
  Rigid3d pose = RefineRelativePose(inliers1, inliers2, PoseFromEssential(E, inliers1, inliers2),
                                    threshold);
  for (int round = 0; reselect && round < 2; ++round) {
    std::vector<char> reselected;
    const int count =
        SelectInliers(EssentialFromPose(pose), points1, points2, threshold, &reselected);
    if (count < 5 || reselected == *mask) break;
    *mask = std::move(reselected);
    inliers1 = Select(points1, *mask);
    inliers2 = Select(points2, *mask);
    pose = RefineRelativePose(inliers1, inliers2, pose, threshold);
  }
  return pose;
}

// USAC's F comes from a small inlier sample: refit it by the normalised 8-point algorithm on
// all inliers and re-select them by Sampson error, while that keeps or adds inliers (at most
// three rounds). Counts inliers by Sampson error even when nothing is refitted, the measure
// used for E, so that the two counts compare.
void PolishFundamental(const std::vector<Eigen::Vector2d>& points1,
                       const std::vector<Eigen::Vector2d>& points2, double threshold,
                       ModelEstimate* F) {
  if (F->inliers.empty()) return;
  F->num_inliers = SelectInliers(F->model, points1, points2, threshold, &F->inliers);
  for (int round = 0; round < 3 && F->num_inliers >= 8; ++round) {
    std::vector<cv::Point2d> inliers1, inliers2;
    for (size_t i = 0; i < points1.size(); ++i) {
      if (!F->inliers[i]) continue;
      inliers1.emplace_back(points1[i].x(), points1[i].y());
      inliers2.emplace_back(points2[i].x(), points2[i].y());
    }
    cv::Mat refit;
    try {
      refit = cv::findFundamentalMat(inliers1, inliers2, cv::FM_8POINT);
    } catch (const cv::Exception&) {
      return;
    }
    if (refit.rows != 3 || refit.cols != 3) return;
    const Eigen::Matrix3d model = ToEigen3(refit);
    std::vector<char> mask;
    const int count = SelectInliers(model, points1, points2, threshold, &mask);
    if (count < F->num_inliers) return;
    const bool changed = mask != F->inliers;
    F->model = model;
    F->inliers = std::move(mask);
    F->num_inliers = count;
    if (!changed) return;
  }
}

// The decomposition of a homography between normalised coordinates with the most matches in
// front of both cameras; t is translation over plane distance (0 for a pure rotation).
Rigid3d PoseFromHomography(const Eigen::Matrix3d& H_normalized,
                           const std::vector<Eigen::Vector2d>& points1,
                           const std::vector<Eigen::Vector2d>& points2) {
  std::vector<cv::Mat> rotations, translations, normals;
  cv::decomposeHomographyMat(ToCv(H_normalized), cv::Mat::eye(3, 3, CV_64F), rotations,
                             translations, normals);
  int best_support = -1;
  Rigid3d best;
  for (size_t k = 0; k < rotations.size(); ++k) {
    const Rigid3d pose = MakeRigid(
        ToEigen3(rotations[k]), Eigen::Vector3d(translations[k].at<double>(0),
                                                translations[k].at<double>(1),
                                                translations[k].at<double>(2)));
    const int support = EvaluatePose(pose, points1, points2).num_in_front;
    if (support > best_support) {
      best_support = support;
      best = pose;
    }
  }
  return best;
}

// The relative pose of a pair whose config is kUncalibrated (E = K2^T F K1, polished on the
// inliers, as COLMAP) or planar-or-panoramic (the decomposition of H; kPlanar or kPanoramic by
// the median ray angle), under the intrinsics K1, K2; inliers are normalised coordinates.
// Sets geometry->cam2_from_cam1, the config of planar-or-panoramic pairs, and E when
// set_essential (from the pose for uncalibrated pairs, K2^T F K1 for planar ones).
PoseSupport SetPoseFromUncalibrated(const Eigen::Matrix3d& K1, const Eigen::Matrix3d& K2,
                                    const std::vector<Eigen::Vector2d>& inliers1,
                                    const std::vector<Eigen::Vector2d>& inliers2,
                                    double threshold_normalized, double min_planar_tri_angle_deg,
                                    bool set_essential, TwoViewGeometry* geometry) {
  Rigid3d pose;
  if (geometry->config == TwoViewGeometry::kUncalibrated) {
    std::vector<char> mask(inliers1.size(), 1);
    pose = PolishPose(K2.transpose() * geometry->F * K1, inliers1, inliers2, threshold_normalized,
                      /*reselect=*/false, &mask);
    if (set_essential) geometry->E = EssentialFromPose(pose);
  } else {
    if (set_essential) geometry->E = K2.transpose() * geometry->F * K1;
    pose = PoseFromHomography(K2.inverse() * geometry->H * K1, inliers1, inliers2);
  }
  const PoseSupport support = EvaluatePose(pose, inliers1, inliers2);
  if (geometry->config != TwoViewGeometry::kUncalibrated) {
    const bool panoramic =
        pose.translation.norm() < 1e-12 || support.median_angle_deg < min_planar_tri_angle_deg;
    geometry->config = panoramic ? TwoViewGeometry::kPanoramic : TwoViewGeometry::kPlanar;
    pose.translation =
        panoramic ? Eigen::Vector3d::Zero() : Eigen::Vector3d(pose.translation.normalized());
  }
  geometry->cam2_from_cam1 = pose;
  return support;
}

}  // namespace

void TwoViewVerificationOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(max_error > 0, "verification max_error must be positive, got {}",
                         max_error);
  LOOPSFM_REQUIRE_OPTION(confidence > 0 && confidence < 1,
                         "verification confidence must be in (0, 1), got {}", confidence);
  LOOPSFM_REQUIRE_OPTION(max_num_trials >= 1,
                         "verification max_num_trials must be at least 1, got {}",
                         max_num_trials);
  LOOPSFM_REQUIRE_OPTION(min_num_inliers >= 8,
                         "verification min_num_inliers must be at least 8, got {}",
                         min_num_inliers);
  LOOPSFM_REQUIRE_OPTION(min_inlier_ratio >= 0 && min_inlier_ratio <= 1,
                         "verification min_inlier_ratio must be in [0, 1], got {}",
                         min_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(min_E_F_inlier_ratio >= 0 && min_E_F_inlier_ratio <= 1,
                         "verification min_E_F_inlier_ratio must be in [0, 1], got {}",
                         min_E_F_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(max_H_inlier_ratio >= 0 && max_H_inlier_ratio <= 1,
                         "verification max_H_inlier_ratio must be in [0, 1], got {}",
                         max_H_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(min_planar_tri_angle_deg >= 0,
                         "verification min_planar_tri_angle_deg must be non-negative, got {}",
                         min_planar_tri_angle_deg);
}

TwoViewVerification VerifyTwoViewGeometry(const Camera& camera1,
                                          const FeatureKeypoints& keypoints1,
                                          const Camera& camera2,
                                          const FeatureKeypoints& keypoints2,
                                          const FeatureMatches& matches,
                                          const TwoViewVerificationOptions& options,
                                          Random& random) {
  options.Check();
  camera1.Check();
  camera2.Check();
  // Seeds are drawn first and always in the same order, so they do not depend on the input.
  const int seed_F = static_cast<int>(random.UniformInt(0, INT_MAX));
  const int seed_H = static_cast<int>(random.UniformInt(0, INT_MAX));
  const int seed_E = static_cast<int>(random.UniformInt(0, INT_MAX));

  TwoViewVerification result;
  TwoViewGeometry& geometry = result.geometry;
  geometry.config = TwoViewGeometry::kDegenerate;
  const size_t n = matches.size();
  result.num_matches = static_cast<int>(n);
  for (const FeatureMatch& m : matches) {
    if (m.point2D_idx1 >= keypoints1.size() || m.point2D_idx2 >= keypoints2.size()) {
      throw InputError(fmt::format(
          "match ({}, {}) refers to a keypoint beyond the images' {} and {} keypoints; the "
          "matches do not belong to these features",
          m.point2D_idx1, m.point2D_idx2, keypoints1.size(), keypoints2.size()));
    }
  }
  if (n < static_cast<size_t>(options.min_num_inliers)) return result;

  std::vector<cv::Point2d> pixels1(n), pixels2(n);
  std::vector<Eigen::Vector2d> pixel_points1(n), pixel_points2(n), normalized1(n), normalized2(n);
  for (size_t i = 0; i < n; ++i) {
    const FeatureKeypoint& k1 = keypoints1[matches[i].point2D_idx1];
    const FeatureKeypoint& k2 = keypoints2[matches[i].point2D_idx2];
    pixels1[i] = {k1.x, k1.y};
    pixels2[i] = {k2.x, k2.y};
    pixel_points1[i] = {k1.x, k1.y};
    pixel_points2[i] = {k2.x, k2.y};
    normalized1[i] = camera1.CamFromImg(Eigen::Vector2d(k1.x, k1.y));
    normalized2[i] = camera2.CamFromImg(Eigen::Vector2d(k2.x, k2.y));
  }
  const double threshold_normalized =
      options.max_error / (0.5 * (camera1.MeanFocalLength() + camera2.MeanFocalLength()));
  const Eigen::Matrix3d K1 = CalibrationMatrix(camera1);
  const Eigen::Matrix3d K2 = CalibrationMatrix(camera2);

  const bool calibrated = camera1.has_prior_focal_length && camera2.has_prior_focal_length;
  ModelEstimate E;
  Rigid3d calibrated_pose;
  if (calibrated) {
    const cv::Mat identity = cv::Mat::eye(3, 3, CV_64F);
    std::vector<cv::Point2d> cv_normalized1(n), cv_normalized2(n);
    for (size_t i = 0; i < n; ++i) {
      cv_normalized1[i] = {normalized1[i].x(), normalized1[i].y()};
      cv_normalized2[i] = {normalized2[i].x(), normalized2[i].y()};
    }
    E = RunEstimator(n, [&](cv::Mat& mask) {
      return cv::findEssentialMat(cv_normalized1, cv_normalized2, identity, identity, cv::Mat(),
                                  cv::Mat(), mask,
                                  MakeUsacParams(options, threshold_normalized, seed_E));
    });
    if (E.num_inliers >= 5) {
      calibrated_pose = PolishPose(E.model, normalized1, normalized2, threshold_normalized,
                                   /*reselect=*/true, &E.inliers);
      E.model = EssentialFromPose(calibrated_pose);
      E.num_inliers = static_cast<int>(std::count(E.inliers.begin(), E.inliers.end(), 1));
    }
  }
  // F is needed only when E might not explain nearly as many matches as F: E with at least
  // min_E_F_inlier_ratio of all matches wins against any F (F's inliers are matches too).
  // Otherwise F comes from E and the intrinsics, and num_F_inliers stays 0 (not estimated).
  ModelEstimate F;
  if (!calibrated || E.num_inliers < options.min_E_F_inlier_ratio * static_cast<double>(n)) {
    F = RunEstimator(n, [&](cv::Mat& mask) {
      return cv::findFundamentalMat(pixels1, pixels2, mask,
                                    MakeUsacParams(options, options.max_error, seed_F));
    });
    PolishFundamental(pixel_points1, pixel_points2, options.max_error, &F);
  } else {
    F.model = K2.transpose().inverse() * E.model * K1.inverse();
  }
  const ModelEstimate H = RunEstimator(n, [&](cv::Mat& mask) {
    return cv::findHomography(pixels1, pixels2, mask,
                              MakeUsacParams(options, options.max_error, seed_H));
  });
  result.num_E_inliers = E.num_inliers;
  result.num_F_inliers = F.num_inliers;
  result.num_H_inliers = H.num_inliers;

  // COLMAP's classification: prefer E, then F, then H.
  const ModelEstimate* best = nullptr;
  int config = TwoViewGeometry::kDegenerate;
  if (calibrated && E.num_inliers >= options.min_num_inliers &&
      E.num_inliers >= options.min_E_F_inlier_ratio * F.num_inliers) {
    result.h_inlier_ratio = static_cast<double>(H.num_inliers) / E.num_inliers;
    const bool planar = result.h_inlier_ratio > options.max_H_inlier_ratio;
    config = planar ? TwoViewGeometry::kPlanarOrPanoramic : TwoViewGeometry::kCalibrated;
    best = planar && H.num_inliers > E.num_inliers ? &H : &E;
  } else if (F.num_inliers >= options.min_num_inliers) {
    result.h_inlier_ratio = static_cast<double>(H.num_inliers) / F.num_inliers;
    const bool planar = result.h_inlier_ratio > options.max_H_inlier_ratio;
    config = planar ? TwoViewGeometry::kPlanarOrPanoramic : TwoViewGeometry::kUncalibrated;
    best = planar && H.num_inliers > F.num_inliers ? &H : &F;
  } else if (H.num_inliers >= options.min_num_inliers) {
    config = TwoViewGeometry::kPlanarOrPanoramic;
    best = &H;
  }
  if (best == nullptr || best->num_inliers < options.min_inlier_ratio * static_cast<double>(n)) {
    return result;
  }

  geometry.config = config;
  geometry.F = F.model;
  geometry.H = H.model;
  const std::vector<char>& inlier_mask = best->inliers;
  PoseSupport support;
  if (config == TwoViewGeometry::kCalibrated) {
    geometry.E = E.model;
    geometry.cam2_from_cam1 = calibrated_pose;
    support = EvaluatePose(calibrated_pose, Select(normalized1, inlier_mask),
                           Select(normalized2, inlier_mask));
  } else {
    const bool calibrated_planar = calibrated && E.num_inliers > 0 &&
                                   config == TwoViewGeometry::kPlanarOrPanoramic;
    if (calibrated_planar) geometry.E = E.model;
    support = SetPoseFromUncalibrated(K1, K2, Select(normalized1, inlier_mask),
                                      Select(normalized2, inlier_mask), threshold_normalized,
                                      options.min_planar_tri_angle_deg,
                                      /*set_essential=*/!calibrated_planar, &geometry);
  }
  result.median_tri_angle_deg = support.median_angle_deg;
  result.num_pose_inliers = support.num_in_front;
  for (size_t i = 0; i < n; ++i) {
    if (inlier_mask[i]) geometry.inlier_matches.push_back(matches[i]);
  }
  return result;
}

void UpdateRelativePose(const Camera& camera1, const std::vector<Eigen::Vector2d>& keypoints1,
                        const Camera& camera2, const std::vector<Eigen::Vector2d>& keypoints2,
                        const TwoViewVerificationOptions& options, TwoViewGeometry* geometry) {
  const int config = geometry->config;
  if (config != TwoViewGeometry::kUncalibrated && config != TwoViewGeometry::kPlanar &&
      config != TwoViewGeometry::kPanoramic && config != TwoViewGeometry::kPlanarOrPanoramic) {
    return;
  }
  std::vector<Eigen::Vector2d> inliers1, inliers2;
  inliers1.reserve(geometry->inlier_matches.size());
  inliers2.reserve(geometry->inlier_matches.size());
  for (const FeatureMatch& m : geometry->inlier_matches) {
    inliers1.push_back(camera1.CamFromImg(keypoints1.at(m.point2D_idx1)));
    inliers2.push_back(camera2.CamFromImg(keypoints2.at(m.point2D_idx2)));
  }
  if (config != TwoViewGeometry::kUncalibrated) geometry->config = TwoViewGeometry::kPlanarOrPanoramic;
  const double threshold_normalized =
      options.max_error / (0.5 * (camera1.MeanFocalLength() + camera2.MeanFocalLength()));
  SetPoseFromUncalibrated(CalibrationMatrix(camera1), CalibrationMatrix(camera2), inliers1,
                          inliers2, threshold_normalized, options.min_planar_tri_angle_deg,
                          /*set_essential=*/true, geometry);
}

namespace {

// The rotation nearest to H (normalised image coordinates) scaled to determinant 1: a
// pair's rotation where its baseline is short against the scene's depth.
std::optional<Eigen::Matrix3d> RotationOfHomography(const Eigen::Matrix3d& H) {
  const double det = H.determinant();
  if (!std::isfinite(det) || std::abs(det) < 1e-12) return std::nullopt;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H / std::cbrt(det),
                                              Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d R = svd.matrixU() * svd.matrixV().transpose();
  if (R.determinant() < 0) return std::nullopt;
  return R;
}

}  // namespace

std::optional<Rigid3d> EssentialPoseOfPair(const Camera& camera1,
                                           const std::vector<Eigen::Vector2d>& keypoints1,
                                           const Camera& camera2,
                                           const std::vector<Eigen::Vector2d>& keypoints2,
                                           const TwoViewVerificationOptions& options,
                                           const TwoViewGeometry& geometry) {
  if (!geometry.F.allFinite() || geometry.F.norm() < 1e-12 || geometry.inlier_matches.size() < 5) {
    return std::nullopt;
  }
  std::vector<Eigen::Vector2d> inliers1, inliers2;
  inliers1.reserve(geometry.inlier_matches.size());
  inliers2.reserve(geometry.inlier_matches.size());
  for (const FeatureMatch& m : geometry.inlier_matches) {
    inliers1.push_back(camera1.CamFromImg(keypoints1.at(m.point2D_idx1)));
    inliers2.push_back(camera2.CamFromImg(keypoints2.at(m.point2D_idx2)));
  }
  const Eigen::Matrix3d K1 = CalibrationMatrix(camera1), K2 = CalibrationMatrix(camera2);
  const double threshold_normalized =
      options.max_error / (0.5 * (camera1.MeanFocalLength() + camera2.MeanFocalLength()));
  Rigid3d pose = PoseFromEssential(K2.transpose() * geometry.F * K1, inliers1, inliers2);
  // Where the baseline is short, the points in front of both cameras barely tell E's two
  // rotations apart (they differ by half a turn about the baseline): the one nearer the
  // homography's rotation is taken.
  const std::optional<Eigen::Matrix3d> R_h =
      geometry.H.allFinite() ? RotationOfHomography(K2.inverse() * geometry.H * K1)
                             : std::nullopt;
  if (R_h && pose.translation.norm() > 0.0) {
    const Eigen::Matrix3d R = pose.rotation.toRotationMatrix();
    const Eigen::Vector3d t = pose.translation.normalized();
    const Eigen::Matrix3d twisted = (2.0 * t * t.transpose() - Eigen::Matrix3d::Identity()) * R;
    const auto angle = [&](const Eigen::Matrix3d& A) {
      return Eigen::AngleAxisd(Eigen::Matrix3d(A * R_h->transpose())).angle();
    };
    if (angle(twisted) < angle(R)) pose.rotation = Eigen::Quaterniond(twisted).normalized();
  }
  return RefineRelativePose(inliers1, inliers2, pose, threshold_normalized);
}

}  // namespace loopsfm
