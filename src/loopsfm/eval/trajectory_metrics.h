#pragma once
// Trajectory metrics of an estimated camera path against ground truth, as described in
// ../shared/data/README.md: the estimated camera centres are aligned to the ground-truth
// centres with a similarity transform (Umeyama), then
//   ATE       RMSE of the aligned centre errors, also as a fraction of the ground-truth
//             path length (summed over ALL ground-truth frames in the order given);
//   rotation  angle of R_gt^T * R_aligned per frame, where R_aligned is the estimated
//             world_from_cam rotation with the alignment's rotation applied;
//   RPE       optional relative pose error between frames `rpe_step` apart in the ground
//             truth, with the alignment's scale applied to the estimated translations;
//   coverage  matched frames over ground-truth frames;
//   loop gap  for each ground-truth revisit (two frames far apart in the sequence whose true
//             centres are close and which look the same way, so that the second sees again
//             what the first saw), the length of the difference between the aligned
//             estimated offset and the true offset between them: how far the two ends of
//             a loop disagree. Drift that is not closed shows here even where the ATE,
//             averaged over the whole path, stays small.
//
// Joining frames by name (see JoinTrajectoriesByName):
//   1. an estimated frame whose name equals the ground-truth name exactly;
//   2. otherwise, when TrajectoryEvalOptions::match_without_extension is set, the one
//      estimated frame whose key equals the ground-truth key, where the key is the file
//      name without folders and without its last extension ("images/frame_000001.jpg" ->
//      "frame_000001"). Keys shared by several estimated frames (or several ground-truth
//      frames) are ambiguous and never used for joining.
// Each estimated frame is joined to at most one ground-truth frame.

#include <cmath>

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/scene/reconstruction.h"

namespace loopsfm {

struct TrajectoryEvalOptions {
  // Fall back to joining names without folders and extension when no exact match exists.
  bool match_without_extension = true;
  // Ground-truth frame distance of the relative pose error pairs; 0 leaves RPE out.
  int rpe_step = 1;
  // Matched frames needed to align and score (the Sim3 needs at least 3).
  int min_matched_frames = 3;
  // Loop gap: a revisit pairs a frame with the closest later frame at least this many
  // ground-truth frames away (0: a fifth of the ground-truth frames, at least 10) whose true
  // centre is within loop_max_distance_steps times the median distance between consecutive
  // ground-truth centres and whose true viewing direction is within loop_max_view_angle_deg
  // of the first's (a place passed looking the other way is not seen again: no method can
  // close a loop there).
  int loop_min_frame_gap = 0;
  double loop_max_distance_steps = 3.0;
  double loop_max_view_angle_deg = 60.0;
  void Check() const;  // throws InvalidArgument
};

// One matched frame.
struct FrameError {
  // Name in the ground truth and in the estimate (they differ when joined by key).
  std::string gt_name;
  std::string estimated_name;
  // Position of the frame in the ground-truth sequence.
  size_t gt_index = 0;
  // Distance between the aligned estimated centre and the ground-truth centre (gt units);
  // NaN when no alignment could be computed.
  double position_error = 0.0;
  // Angle of R_gt^T * R_aligned in degrees; NaN when no alignment could be computed.
  double rotation_error_deg = 0.0;
  // The estimated centre mapped into the ground-truth world by the alignment (NaN when
  // none could be computed).
  Eigen::Vector3d aligned_centre = Eigen::Vector3d::Constant(std::nan(""));
};

// Relative pose errors over the pairs (k, k + step) of ground-truth frames that are both
// matched. For a pair, E = gt_rel^-1 * est_rel with rel = cam_k_from_cam_{k+step} and the
// estimated translation scaled by the alignment's scale.
struct RelativePoseErrors {
  int step = 0;
  size_t num_pairs = 0;
  // RMSE / mean / max of |translation(E)| in gt units.
  double translation_rmse = 0.0;
  double translation_mean = 0.0;
  double translation_max = 0.0;
  // Mean / max of the rotation angle of E in degrees.
  double rotation_mean_deg = 0.0;
  double rotation_max_deg = 0.0;
};

// Loop gaps over the ground-truth revisits whose two frames are both matched.
struct LoopGaps {
  int min_frame_gap = 0;
  // Largest distance between the true centres of a revisit's two frames (gt units).
  double max_distance = 0.0;
  size_t num_revisits = 0;
  // |(aligned c_j - aligned c_i) - (gt c_j - gt c_i)| statistics, gt units.
  double mean = 0.0;
  double median = 0.0;
  double max = 0.0;
  // The revisit with the largest gap (ground-truth names).
  std::string max_first, max_second;
};

struct TrajectoryMetrics {
  size_t num_gt_frames = 0;
  size_t num_estimated = 0;
  // Frames present in both (joined by name).
  size_t num_matched = 0;
  // num_matched / num_gt_frames (0 when there is no ground truth).
  double fraction_registered = 0.0;
  // Sum of distances between consecutive ground-truth centres, all frames, in file order.
  double gt_path_length = 0.0;

  // False when there were too few matches or the centres were degenerate (e.g. all on
  // one line); `explanation` then says why and the error fields below are NaN.
  bool aligned = false;
  std::string explanation;
  // gt_world_from_estimated_world (Umeyama on camera centres).
  Sim3d gt_from_estimated;

  // Absolute trajectory error of the aligned centres, gt units.
  double ate_rmse = 0.0;
  double ate_mean = 0.0;
  double ate_median = 0.0;
  double ate_max = 0.0;
  // ate_rmse / gt_path_length (NaN when the path length is zero).
  double ate_fraction_of_path = 0.0;

  // Orientation errors after alignment, degrees.
  double rotation_error_mean_deg = 0.0;
  double rotation_error_median_deg = 0.0;
  double rotation_error_max_deg = 0.0;
  // How well the centres fix the alignment's roll about their main axis (the principal
  // direction of the ground-truth centres), degrees: the standard error of that angle in the
  // least-squares fit: the RMS of the aligned centres' errors across the axis over the root
  // of the ground-truth centres' summed squared distances from it. Centres nearly on a line (a straight walk) leave the roll to the
  // shake across it, and the rotation errors above then measure mostly that roll; the
  // relative pose error at a long step does not depend on the alignment.
  double alignment_roll_uncertainty_deg = 0.0;

  // Present when options.rpe_step > 0 and the alignment succeeded.
  std::optional<RelativePoseErrors> rpe;
  // Present when the alignment succeeded; num_revisits is 0 where the path never returns.
  std::optional<LoopGaps> loop_gaps;

  // Matched frames in ground-truth order.
  std::vector<FrameError> frames;
};

// One matched pair of frames: indices into the ground-truth and the estimated list.
struct FrameMatch {
  size_t gt_index = 0;
  size_t estimated_index = 0;
};

// Joins the two lists by name as described at the top of this file; sorted by gt_index.
std::vector<FrameMatch> JoinTrajectoriesByName(const std::vector<TrajectoryEntry>& estimated,
                                               const std::vector<TrajectoryEntry>& ground_truth,
                                               bool match_without_extension);

// The key used for the fallback join: file name without folders and last extension.
std::string TrajectoryNameKey(const std::string& name);

// world_from_cam of every registered image, sorted by name.
std::vector<TrajectoryEntry> TrajectoryFromReconstruction(const Reconstruction& reconstruction);

// Sum of the distances between consecutive centres, in the order given.
double TrajectoryPathLength(const std::vector<TrajectoryEntry>& trajectory);

// Scores `estimated` (world_from_cam poses, any order) against `ground_truth` (in capture
// order). Never throws for too few matches: the metrics then say why they are empty.
TrajectoryMetrics EvaluateTrajectory(const std::vector<TrajectoryEntry>& estimated,
                                     const std::vector<TrajectoryEntry>& ground_truth,
                                     const TrajectoryEvalOptions& options = {});
// Same for the registered images of a reconstruction.
TrajectoryMetrics EvaluateTrajectory(const Reconstruction& reconstruction,
                                     const std::vector<TrajectoryEntry>& ground_truth,
                                     const TrajectoryEvalOptions& options = {});

// Metrics as JSON: counts, path length, alignment (scale, quaternion wxyz, translation),
// ATE / rotation / RPE statistics (null where NaN) and, when include_frames, the per-frame
// errors. Field names match the struct members.
nlohmann::json ToJson(const TrajectoryMetrics& metrics, bool include_frames = true);

}  // namespace loopsfm
