#include "loopsfm/pipeline/global_mapper_checkpoint.h"

#include <cmath>
#include <set>
#include <utility>
#include <vector>

#include "loopsfm/pipeline/checkpoint_file.h"
#include "loopsfm/pipeline/mapper_checkpoint.h"
#include "loopsfm/pipeline/wire_format.h"
#include "loopsfm/util/byte_io.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

// JSON for the options in the fingerprint and the reports in the header. Enums are written
// as their numbers; GlobalPositioningOptions::num_threads is left out (it changes rounding
// only, and the mapper sets it).
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(ViewGraphCleaningOptions, max_loop_error_deg,
                                   min_pass_fraction, weigh_triangles,
                                   keep_largest_component)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(TwoViewVerificationOptions, max_error, confidence,
                                   max_num_trials, min_num_inliers, min_inlier_ratio,
                                   min_E_F_inlier_ratio, max_H_inlier_ratio,
                                   min_planar_tri_angle_deg)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RotationAveragingOptions, initialization, agreement_deg,
                                   num_l1_iterations, num_l1_inner_iterations,
                                   max_num_iterations, convergence_threshold_deg,
                                   robust_scale_deg, use_weights, outlier_threshold_deg)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(GlobalPositioningOptions, loss, loss_scale,
                                   random_init_extent, min_scale, min_num_views_per_point,
                                   camera_direction_weight, max_angle_error_deg,
                                   retriangulate_points, normalize_gauge, linear_solver,
                                   max_num_iterations, function_tolerance, settle_tolerance,
                                   seed)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(GlobalMapperOptions, view_graph, verification,
                                   planar_pose_by_triangles, split_at_cuts, rotation_averaging, max_rotation_error_deg, positioning,
                                   min_track_length, max_tracks_per_frame,
                                   max_observations_per_track, max_off_observation_fraction, stop_when_bent,
                                   pair_directions,
                                   chained_start, loose_error_factor, num_loose_rounds,
                                   loose_points_per_frame, loose_settle_tolerance,
                                   num_refinement_rounds,
                                   min_frame_points, max_step_ratio)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(ViewGraphCleaningReport, num_input_edges, num_ignored_edges,
                                   num_triangles, num_failed_triangles, num_edges_in_no_triangle,
                                   num_dropped_by_triangles, num_dropped_outside_component,
                                   num_nodes, num_edges, time_s)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RotationAveragingReport, success, converged, num_input_edges,
                                   num_ignored_edges, num_nodes, num_edges, num_l1_iterations,
                                   num_iterations, final_update_deg, edge_residual_deg,
                                   num_outlier_edges, time_s)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(GlobalPositioningReport, success, num_cameras, num_points,
                                   num_unconstrained_cameras, num_skipped_points,
                                   num_observations, num_camera_directions,
                                   num_large_angle_observations, num_retriangulated_points,
                                   num_iterations, initial_cost, final_cost, time_s,
                                   termination)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(GlobalMapperReport, num_view_graph_edges, num_cuts,
                                   num_pairs_across_cuts,
                                   num_planar_pairs, num_planar_poses_from_homography, view_graph,
                                   num_components, num_components_mapped,
                                   num_frames_in_other_components, rotations,
                                   num_rotation_outliers, num_frames_without_edges,
                                   num_tracks_positioned, positioning, num_bent_components,
                                   num_frames_dropped,
                                   num_frames, num_registered, largest_step_ratio,
                                   largest_step_from, largest_step_to, num_broken_models,
                                   seconds_view_graph,
                                   seconds_rotations, seconds_positioning,
                                   seconds_triangulation, seconds_bundles, seconds_joining)

namespace fs = std::filesystem;
namespace {

const CheckpointFormat kFormat{"loopsfm global mapper checkpoint\n", 1};

bool IsRotation(const Eigen::Quaterniond& q) {
  return q.coeffs().allFinite() && std::abs(q.norm() - 1.0) < 1e-6;
}

// nlohmann's get<int>() of a number past int's range is undefined behaviour; a report's
// numbers are all well inside it.
void CheckNumbers(const nlohmann::json& j) {
  if (j.is_structured()) {
    for (const nlohmann::json& value : j) CheckNumbers(value);
  } else if (j.is_number_float() && !(std::abs(j.get<double>()) < 2147483647.0)) {
    throw InputError(fmt::format("its header has the number {}, out of range", j.dump()));
  }
}

void PutComponent(ByteWriter& w, const GlobalMapperCheckpoint::Component& c) {
  w.Put<uint64_t>(c.edges.size());
  for (const RelativeRotation& edge : c.edges) {
    w.Put(edge.node1);
    w.Put(edge.node2);
    PutRotation(w, edge.cam2_from_cam1);
    w.Put(edge.weight);
  }
  if (c.rotations) {
    w.Put<uint64_t>(c.rotations->size());
    for (const auto& [id, rotation] : *c.rotations) {
      w.Put(id);
      PutRotation(w, rotation);
    }
  }
  if (c.positioned) {
    w.Put<uint64_t>(c.positioned->size());
    for (const auto& [id, pose] : *c.positioned) {
      w.Put(id);
      PutPose(w, pose);
    }
  }
  if (c.loose) PutMappedState(w, *c.loose);
  if (c.model) PutMappedState(w, *c.model);
}

// The state, checked against the input: it must restore onto its frames.
MappedState GetCheckedState(ByteReader& r, const MapperInput& input) {
  MappedState state = GetMappedState(r);
  EmptyReconstruction(input).RestoreMapped(state);  // throws InputError where it does not fit
  return state;
}

// One component as the header describes it, its values checked against the input.
GlobalMapperCheckpoint::Component GetComponent(ByteReader& r, const nlohmann::json& header,
                                               const std::set<image_t>& frames,
                                               const MapperInput& input) {
  auto check_frame = [&](image_t id) {
    if (frames.count(id) == 0) {
      throw InputError(fmt::format("it names frame {}, which the input does not have", id));
    }
  };
  GlobalMapperCheckpoint::Component c;
  const uint64_t num_edges = r.GetCount(2 * sizeof(image_t) + 5 * sizeof(double));
  for (uint64_t k = 0; k < num_edges; ++k) {
    RelativeRotation edge;
    edge.node1 = r.Get<image_t>();
    edge.node2 = r.Get<image_t>();
    edge.cam2_from_cam1 = GetRotation(r);
    edge.weight = r.Get<double>();
    check_frame(edge.node1);
    check_frame(edge.node2);
    if (!IsRotation(edge.cam2_from_cam1) || !(edge.weight > 0.0)) {
      throw InputError("it has an edge without a rotation or a weight");
    }
    c.edges.push_back(edge);
  }
  if (header.at("rotations").get<bool>()) {
    c.rotations.emplace();
    const uint64_t count = r.GetCount(sizeof(image_t) + 4 * sizeof(double));
    for (uint64_t k = 0; k < count; ++k) {
      const image_t id = r.Get<image_t>();
      const Eigen::Quaterniond rotation = GetRotation(r);
      check_frame(id);
      if (!IsRotation(rotation)) throw InputError("it has a rotation that is not one");
      (*c.rotations)[id] = rotation;
    }
  }
  if (header.at("positioned").get<bool>()) {
    c.positioned.emplace();
    const uint64_t count = r.GetCount(sizeof(image_t) + 7 * sizeof(double));
    for (uint64_t k = 0; k < count; ++k) {
      const image_t id = r.Get<image_t>();
      const Rigid3d pose = GetPose(r);
      check_frame(id);
      if (!IsRotation(pose.rotation) || !pose.translation.allFinite()) {
        throw InputError("it has a pose that is not one");
      }
      (*c.positioned)[id] = pose;
    }
  }
  if (header.at("loose").get<bool>()) c.loose = GetCheckedState(r, input);
  c.done = header.at("done").get<bool>();
  if (header.at("model").get<bool>()) c.model = GetCheckedState(r, input);
  return c;
}

}  // namespace

nlohmann::json GlobalMapperCheckpointFingerprint(const MapperInput& input,
                                                 const IncrementalMapperOptions& mapper_options,
                                                 const GlobalMapperOptions& options) {
  nlohmann::json fingerprint = MapperCheckpointFingerprint(input, mapper_options);
  fingerprint["global"] = options;
  return fingerprint;
}

void WriteGlobalMapperCheckpoint(const fs::path& path, const GlobalMapperCheckpoint& checkpoint,
                                 const nlohmann::json& fingerprint) {
  nlohmann::json components = nlohmann::json::array();
  ByteWriter body;
  for (const GlobalMapperCheckpoint::Component& c : checkpoint.components) {
    components.push_back({{"rotations", c.rotations.has_value()},
                          {"positioned", c.positioned.has_value()},
                          {"loose", c.loose.has_value()},
                          {"done", c.done},
                          {"model", c.model.has_value()}});
    PutComponent(body, c);
  }
  const nlohmann::json header = {{"components", components},
                                 {"report", checkpoint.report},
                                 {"mapper_report", MapperReportJson(checkpoint.mapper_report)}};
  WriteCheckpointFile(path, kFormat, header, fingerprint, body.Bytes());
}

std::optional<GlobalMapperCheckpoint> ReadGlobalMapperCheckpoint(
    const fs::path& path, const MapperInput& input, const nlohmann::json& fingerprint) {
  std::set<image_t> frames;
  for (const MapperFrame& frame : input.frames) frames.insert(frame.image_id);
  GlobalMapperCheckpoint checkpoint;
  const bool read = ReadCheckpointFile(
      path, kFormat, fingerprint, [&](const nlohmann::json& header, ByteReader& body) {
        CheckNumbers(header.at("report"));
        checkpoint.report = header.at("report").get<GlobalMapperReport>();
        checkpoint.mapper_report = MapperReportFromJson(header.at("mapper_report"));
        for (const nlohmann::json& component : header.at("components")) {
          checkpoint.components.push_back(GetComponent(body, component, frames, input));
        }
      });
  if (!read) return std::nullopt;
  return checkpoint;
}

GlobalMapperCheckpointFile::GlobalMapperCheckpointFile(
    std::filesystem::path path, const MapperInput& input,
    const IncrementalMapperOptions& mapper_options, const GlobalMapperOptions& options)
    : path_(std::move(path)),
      fingerprint_(GlobalMapperCheckpointFingerprint(input, mapper_options, options)),
      resume_(ReadGlobalMapperCheckpoint(path_, input, fingerprint_)) {
  if (resume_) checkpointing_.resume = &*resume_;
  checkpointing_.save = [this](const GlobalMapperCheckpoint& checkpoint) {
    WriteGlobalMapperCheckpoint(path_, checkpoint, fingerprint_);
  };
}

}  // namespace loopsfm
