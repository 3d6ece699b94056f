#include "loopsfm/sfm/mapper_options.h"

#include <algorithm>

#include "loopsfm/util/errors.h"

namespace loopsfm {

IntrinsicsRefinement IntrinsicsRefinement::Parse(const std::string& text) {
  IntrinsicsRefinement refine;
  if (text == "none") return refine;
  std::string::size_type begin = 0;
  while (begin <= text.size()) {
    const std::string::size_type end = std::min(text.find(',', begin), text.size());
    const std::string word = text.substr(begin, end - begin);
    if (word == "focal") {
      refine.focal_length = true;
    } else if (word == "principal-point") {
      refine.principal_point = true;
    } else if (word == "distortion") {
      refine.distortion = true;
    } else {
      throw InvalidArgument(fmt::format(
          "cannot refine '{}' (in '{}'); list any of focal, principal-point, distortion, "
          "separated by commas, or give none", word, text));
    }
    begin = end + 1;
  }
  return refine;
}

std::string IntrinsicsRefinement::ToString() const {
  std::string text;
  auto add = [&](bool on, const char* word) {
    if (!on) return;
    if (!text.empty()) text += ',';
    text += word;
  };
  add(focal_length, "focal");
  add(principal_point, "principal-point");
  add(distortion, "distortion");
  return text.empty() ? "none" : text;
}

void IncrementalMapperOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(focal_prior_sigma_log >= 0, "focal prior sigma must not be negative, got {}",
                         focal_prior_sigma_log);
  LOOPSFM_REQUIRE_OPTION(!refine_known.Any() || !refine_unknown.Any() ||
                             refine_known.ToString() == refine_unknown.ToString(),
                         "known and unknown intrinsics must be refined alike, or one not at all "
                         "(got {} and {})", refine_known.ToString(), refine_unknown.ToString());
  LOOPSFM_REQUIRE_OPTION(init_min_num_inliers >= 16, "initial pair needs at least 16 inliers, got {}",
                         init_min_num_inliers);
  LOOPSFM_REQUIRE_OPTION(init_max_h_inlier_ratio > 0 && init_max_h_inlier_ratio <= 1,
                         "initial homography inlier ratio must be in (0, 1], got {}",
                         init_max_h_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(init_min_tri_angle_deg > 0, "initial triangulation angle must be positive");
  LOOPSFM_REQUIRE_OPTION(init_min_num_points >= 8, "initial model needs at least 8 points, got {}",
                         init_min_num_points);
  LOOPSFM_REQUIRE_OPTION(init_max_trials >= 1, "at least one initial pair must be tried");
  LOOPSFM_REQUIRE_OPTION(abs_pose_max_error_px > 0, "registration error threshold must be positive");
  LOOPSFM_REQUIRE_OPTION(abs_pose_min_num_inliers >= 4, "registration needs at least 4 inliers");
  LOOPSFM_REQUIRE_OPTION(registration_retry_growth > 1.0,
                         "registration retry growth must be above 1, got {}", registration_retry_growth);
  LOOPSFM_REQUIRE_OPTION(max_reproj_error_px > 0, "reprojection error threshold must be positive");
  LOOPSFM_REQUIRE_OPTION(min_tri_angle_deg >= 0, "triangulation angle must not be negative");
  LOOPSFM_REQUIRE_OPTION(local_ba_num_images >= 1, "local bundle needs at least one image");
  LOOPSFM_REQUIRE_OPTION(global_ba_growth > 0, "global bundle growth must be positive");
  LOOPSFM_REQUIRE_OPTION(global_ba_end_margin >= 0, "global bundle end margin must be 0 or more");
  LOOPSFM_REQUIRE_OPTION(global_ba_window == 0 || global_ba_window >= 20,
                         "global bundle window must be 0 (off) or at least 20 frames, got {}",
                         global_ba_window);
  LOOPSFM_REQUIRE_OPTION(registration_capture_window >= 0 && registration_neighbour_window >= 0,
                         "registration capture and neighbour windows must be >= 0, got {} and {}",
                         registration_capture_window, registration_neighbour_window);
  LOOPSFM_REQUIRE_OPTION(max_num_models >= 1, "at least one model must be allowed");
  LOOPSFM_REQUIRE_OPTION(min_model_size >= 2, "models need at least 2 frames, got {}", min_model_size);
  LOOPSFM_REQUIRE_OPTION(merge_max_reproj_error_px > 0, "merge error threshold must be positive");
  LOOPSFM_REQUIRE_OPTION(merge_min_num_inliers >= 3, "model merging needs at least 3 inliers");
  LOOPSFM_REQUIRE_OPTION(merge_min_inlier_ratio > 0 && merge_min_inlier_ratio <= 1,
                         "merge inlier ratio must be in (0, 1], got {}", merge_min_inlier_ratio);
  loop_closure.Check();
}

void LoopClosureOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_frame_gap >= 2, "loop: frame gap must be at least 2, got {}",
                         min_frame_gap);
  LOOPSFM_REQUIRE_OPTION(min_frame_correspondences >= 3 && min_frame_inliers >= 3 &&
                             min_num_inliers >= 3,
                         "loop: correspondence and inlier counts must be at least 3");
  LOOPSFM_REQUIRE_OPTION(num_consistent >= 1, "loop: at least one registration must agree");
  LOOPSFM_REQUIRE_OPTION(min_inlier_ratio > 0 && min_inlier_ratio <= 1,
                         "loop: inlier ratio must be in (0, 1], got {}", min_inlier_ratio);
  LOOPSFM_REQUIRE_OPTION(max_reproj_error_px > 0, "loop: error threshold must be positive");
  LOOPSFM_REQUIRE_OPTION(max_correction_fraction_of_path > 0,
                         "loop: correction bound must be positive");
  LOOPSFM_REQUIRE_OPTION(max_correction_scale >= 1.0, "loop: scale bound must be at least 1");
  LOOPSFM_REQUIRE_OPTION(covisibility_min_points >= 1, "loop: co-visibility needs a point");
  LOOPSFM_REQUIRE_OPTION(loop_edge_weight > 0, "loop: edge weight must be positive");
  LOOPSFM_REQUIRE_OPTION(split_weight > 0, "loop: split weight must be positive");
  LOOPSFM_REQUIRE_OPTION(refine_points_per_frame >= 0,
                         "loop: refine_points_per_frame must be >= 0 (got {})",
                         refine_points_per_frame);
  LOOPSFM_REQUIRE_OPTION(refine_function_tolerance > 0 && refine_function_tolerance < 1,
                         "loop: refine_function_tolerance must be in (0, 1) (got {})",
                         refine_function_tolerance);
  LOOPSFM_REQUIRE_OPTION(polish_settle_tolerance >= 0,
                         "loop: polish_settle_tolerance must be >= 0 (got {})",
                         polish_settle_tolerance);
  LOOPSFM_REQUIRE_OPTION(split_refine_ties_per_group > 0,
                         "loop: split_refine_ties_per_group must be positive (got {})",
                         split_refine_ties_per_group);
}

}  // namespace loopsfm
