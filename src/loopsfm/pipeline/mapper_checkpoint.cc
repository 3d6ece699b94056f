#include "loopsfm/pipeline/mapper_checkpoint.h"

#include <cstring>
#include <limits>
#include <type_traits>
#include <utility>

#include "loopsfm/pipeline/checkpoint_file.h"
#include "loopsfm/pipeline/wire_format.h"
#include "loopsfm/util/byte_io.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"

namespace loopsfm {
namespace fs = std::filesystem;
namespace {

const CheckpointFormat kFormat{"loopsfm mapper checkpoint\n", 5};

// FNV-1a over the bytes of what mapping reads.
class Digest {
 public:
  void Add(const void* data, size_t size) {
    const auto* bytes = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < size; ++i) hash_ = (hash_ ^ bytes[i]) * 0x100000001b3ull;
  }
  template <typename T>
  void Add(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    Add(&value, sizeof(T));
  }
  template <typename T>
  void AddAll(const std::vector<T>& values) {
    Add(values.size());
    if (!values.empty()) Add(values.data(), values.size() * sizeof(T));
  }
  void Add(const std::string& text) {
    Add(text.size());
    Add(text.data(), text.size());
  }
  std::string Hex() const { return fmt::format("{:016x}", hash_); }

 private:
  uint64_t hash_ = 0xcbf29ce484222325ull;
};

std::string InputDigest(const MapperInput& input) {
  Digest digest;
  for (const Camera& camera : input.cameras) {
    digest.Add(camera.camera_id);
    digest.Add(static_cast<int>(camera.model_id));
    digest.Add(camera.width);
    digest.Add(camera.height);
    digest.AddAll(camera.params);
    digest.Add(camera.has_prior_focal_length);
  }
  for (const MapperFrame& frame : input.frames) {
    digest.Add(frame.image_id);
    digest.Add(frame.camera_id);
    digest.Add(frame.name);
    digest.Add(frame.points2D.size());
    digest.Add(frame.points2D.data(), frame.points2D.size() * sizeof(Eigen::Vector2d));
  }
  for (const MapperPair& pair : input.pairs) {
    digest.Add(pair.pair.image_id1);
    digest.Add(pair.pair.image_id2);
    digest.Add(pair.geometry.config);
    digest.AddAll(pair.geometry.inlier_matches);
  }
  for (const Track& track : input.tracks) digest.AddAll(track.elements);
  return digest.Hex();
}

nlohmann::json RefinementJson(const IntrinsicsRefinement& refine) { return refine.ToString(); }

// Every option that changes what the mapper does (the thread count only changes rounding).
nlohmann::json OptionsJson(const IncrementalMapperOptions& o) {
  const LoopClosureOptions& l = o.loop_closure;
  return {
      {"init", {o.init_min_num_inliers, o.init_max_h_inlier_ratio, o.init_min_tri_angle_deg,
                o.init_min_num_points, o.init_max_trials}},
      {"registration", {o.abs_pose_max_error_px, o.abs_pose_min_num_inliers,
                        o.abs_pose_min_inlier_ratio, o.registration_retry_growth,
                        o.record_alternate_poses, o.registration_capture_window,
                        o.registration_neighbour_window}},
      {"structure", {o.max_reproj_error_px, o.min_tri_angle_deg}},
      {"bundles", {o.local_ba_num_images, o.global_ba_growth, o.global_ba_end_margin,
                   o.global_ba_window, RefinementJson(o.refine_unknown),
                   RefinementJson(o.refine_known), o.focal_prior_sigma_log}},
      {"models", {o.max_num_models, o.min_model_size, o.merge_max_reproj_error_px,
                  o.merge_min_num_inliers, o.merge_min_inlier_ratio}},
      {"loop_closure",
       {static_cast<int>(l.method), l.withhold_loop_pairs, l.min_frame_gap,
        l.min_frame_correspondences, l.num_consistent, l.min_frame_inliers, l.min_num_inliers,
        l.min_inlier_ratio, l.max_reproj_error_px, l.max_correction_fraction_of_path,
        l.max_correction_scale, l.covisibility_min_points, l.loop_edge_weight, l.split_weight,
        l.refine_points_per_frame, l.polish_settle_tolerance, l.refine_function_tolerance}},
      {"seed", o.seed},
  };
}

// ---- binary models -------------------------------------------------------------------

// ---- JSON header ---------------------------------------------------------------------

// A whole number of type T. nlohmann's get<T>() converts any number unchecked: a float past
// T's range (1e20, or an integer too long for 64 bits, which it parses as a float) is
// undefined behaviour, and an integer past it wraps.
template <typename T>
T GetInt(const nlohmann::json& j) {
  static_assert(std::is_integral_v<T>);
  if (j.is_number_unsigned()) {
    const auto value = j.get<uint64_t>();
    if (std::in_range<T>(value)) return static_cast<T>(value);
  } else if (j.is_number_integer()) {
    const auto value = j.get<int64_t>();
    if (std::in_range<T>(value)) return static_cast<T>(value);
  }
  throw InputError(fmt::format("its header has {} where a whole number from {} to {} belongs",
                               j.is_number() ? j.dump() : std::string(j.type_name()),
                               std::numeric_limits<T>::min(), std::numeric_limits<T>::max()));
}

template <typename T>
std::vector<T> GetInts(const nlohmann::json& j) {
  std::vector<T> values;
  for (const nlohmann::json& value : j.get_ref<const nlohmann::json::array_t&>()) {
    values.push_back(GetInt<T>(value));
  }
  return values;
}

nlohmann::json PoseJson(const Rigid3d& pose) {
  const auto& q = pose.rotation.coeffs();
  const auto& t = pose.translation;
  return {q[0], q[1], q[2], q[3], t[0], t[1], t[2]};
}

Rigid3d PoseFromJson(const nlohmann::json& j) {
  const std::vector<double> v = j.get<std::vector<double>>();
  if (v.size() != 7) throw InputError("a pose is not 7 numbers");
  Rigid3d pose;
  pose.rotation.coeffs() << v[0], v[1], v[2], v[3];
  pose.translation << v[4], v[5], v[6];
  return pose;
}

}  // namespace

nlohmann::json MapperReportJson(const MapperReport& r) {
  nlohmann::json loops = nlohmann::json::array();
  for (const ClosedLoop& l : r.loops_closed) {
    loops.push_back({l.recent_frame, l.old_frame, l.num_correspondences, l.num_inliers,
                     l.correction_translation, l.correction_fraction_of_path,
                     l.correction_rotation_deg, l.correction_scale, l.num_points_before,
                     l.num_points_after, l.seconds});
  }
  nlohmann::json path = nlohmann::json::array();
  for (const TrajectoryEntry& e : r.path_before_loop_closing) {
    path.push_back({e.name, PoseJson(e.world_from_cam)});
  }
  nlohmann::json links = nlohmann::json::array();
  for (const LoopLink& l : r.loop_links) {
    links.push_back({l.method, l.old_frame, l.recent_frame, l.num_point_pairs});
  }
  nlohmann::json registrations = nlohmann::json::array();
  for (const RegistrationRounds& g : r.registrations) {
    registrations.push_back({g.frame, g.num_correspondences, g.num_inliers,
                             g.second_num_correspondences, g.second_num_inliers,
                             g.second_pose_found, g.second_centre_distance,
                             g.second_rotation_deg});
  }
  return {
      {"counts", {r.num_models, r.num_registered, r.num_init_trials, r.num_init_accepted,
                  r.num_registered_on_retry, r.num_models_merged, r.num_models_discarded,
                  r.num_local_ba, r.num_global_ba, r.num_local_ba_iterations,
                  r.num_local_ba_residuals, r.num_global_ba_iterations,
                  r.num_global_ba_residuals, r.num_failed_bundles, r.num_failed_pose_refinements,
                  r.num_poses_against_neighbours, r.num_poses_from_neighbours,
                  r.num_poses_undone_by_neighbours, r.num_loops_refused,
                  r.num_split_groups, r.num_split_groups_refused, r.num_split_pairs}},
      {"seconds", {r.seconds_registration, r.seconds_triangulation, r.seconds_local_ba,
                   r.seconds_global_ba, r.seconds_merging, r.seconds_loop_detection,
                   r.seconds_loop_closing, r.seconds_split, r.seconds_checkpoints}},
      {"loops_closed", loops},
      {"path_before_loop_closing", path},
      {"loop_links", links},
      {"registrations", registrations},
  };
}

MapperReport MapperReportFromJson(const nlohmann::json& j) {
  MapperReport r;
  const nlohmann::json& c = j.at("counts");
  if (c.size() != 22) throw InputError("the report's counts are not 22 numbers");
  int k = 0;
  for (int* field : {&r.num_models, &r.num_registered, &r.num_init_trials, &r.num_init_accepted,
                     &r.num_registered_on_retry, &r.num_models_merged, &r.num_models_discarded,
                     &r.num_local_ba, &r.num_global_ba}) {
    *field = GetInt<int>(c.at(k++));
  }
  for (long long* field : {&r.num_local_ba_iterations, &r.num_local_ba_residuals,
                           &r.num_global_ba_iterations, &r.num_global_ba_residuals}) {
    *field = GetInt<long long>(c.at(k++));
  }
  for (int* field : {&r.num_failed_bundles, &r.num_failed_pose_refinements,
                     &r.num_poses_against_neighbours, &r.num_poses_from_neighbours,
                     &r.num_poses_undone_by_neighbours, &r.num_loops_refused, &r.num_split_groups,
                     &r.num_split_groups_refused, &r.num_split_pairs}) {
    *field = GetInt<int>(c.at(k++));
  }
  const nlohmann::json& s = j.at("seconds");
  k = 0;
  for (double* field : {&r.seconds_registration, &r.seconds_triangulation, &r.seconds_local_ba,
                        &r.seconds_global_ba, &r.seconds_merging, &r.seconds_loop_detection,
                        &r.seconds_loop_closing, &r.seconds_split, &r.seconds_checkpoints}) {
    *field = s.at(k++).get<double>();
  }
  for (const nlohmann::json& l : j.at("loops_closed")) {
    r.loops_closed.push_back({l.at(0).get<std::string>(), l.at(1).get<std::string>(),
                              GetInt<int>(l.at(2)), GetInt<int>(l.at(3)), l.at(4).get<double>(),
                              l.at(5).get<double>(), l.at(6).get<double>(), l.at(7).get<double>(),
                              GetInt<long long>(l.at(8)), GetInt<long long>(l.at(9)),
                              l.at(10).get<double>()});
  }
  for (const nlohmann::json& e : j.at("path_before_loop_closing")) {
    r.path_before_loop_closing.push_back({e.at(0).get<std::string>(), PoseFromJson(e.at(1))});
  }
  for (const nlohmann::json& l : j.at("loop_links")) {
    r.loop_links.push_back({l.at(0).get<std::string>(), l.at(1).get<std::string>(),
                            l.at(2).get<std::string>(), GetInt<int>(l.at(3))});
  }
  for (const nlohmann::json& g : j.at("registrations")) {
    r.registrations.push_back({g.at(0).get<std::string>(), GetInt<int>(g.at(1)),
                               GetInt<int>(g.at(2)), GetInt<int>(g.at(3)), GetInt<int>(g.at(4)),
                               g.at(5).get<bool>(), g.at(6).get<double>(), g.at(7).get<double>()});
  }
  return r;
}

namespace {

nlohmann::json ModelJson(const MapperCheckpoint::Model& model) {
  return {{"gauge", {model.gauge1, model.gauge2}}, {"merge_failures", model.merge_failures}};
}

MapperCheckpoint::Model ModelFromJson(const nlohmann::json& j) {
  MapperCheckpoint::Model model;
  model.gauge1 = GetInt<image_t>(j.at("gauge").at(0));
  model.gauge2 = GetInt<image_t>(j.at("gauge").at(1));
  model.merge_failures = GetInt<int>(j.at("merge_failures"));
  return model;
}

nlohmann::json HeaderJson(const MapperCheckpoint& c) {
  nlohmann::json kept = nlohmann::json::array();
  for (const MapperCheckpoint::Model& model : c.kept) kept.push_back(ModelJson(model));
  std::string tried;
  for (const char t : c.tried_initial_pairs) tried += t ? '1' : '0';
  return {
      {"finished", c.finished},
      {"kept", kept},
      {"growing", c.growing ? ModelJson(*c.growing) : nlohmann::json()},
      {"failed_at", c.failed_at},
      {"ever_failed", c.ever_failed},
      {"last_global_size", c.last_global_size},
      {"recent_frames", c.recent_frames},
      {"refined_since_stall", c.refined_since_stall},
      {"tried_initial_pairs", tried},
      {"random_state", c.random_state},
      {"loop_random_state", c.loop_random_state},
      {"loop_window", c.loop_window},
      {"loop_cooldown", c.loop_cooldown},
      {"report", MapperReportJson(c.report)},
  };
}

MapperCheckpoint CheckpointFromHeader(const nlohmann::json& j) {
  MapperCheckpoint c;
  c.finished = j.at("finished").get<bool>();
  for (const nlohmann::json& model : j.at("kept")) c.kept.push_back(ModelFromJson(model));
  if (!j.at("growing").is_null()) c.growing = ModelFromJson(j.at("growing"));
  for (const nlohmann::json& f : j.at("failed_at").get_ref<const nlohmann::json::array_t&>()) {
    c.failed_at.emplace_back(GetInt<image_t>(f.at(0)), GetInt<uint64_t>(f.at(1)));
  }
  c.ever_failed = GetInts<image_t>(j.at("ever_failed"));
  c.last_global_size = GetInt<uint64_t>(j.at("last_global_size"));
  c.recent_frames = GetInts<image_t>(j.at("recent_frames"));
  c.refined_since_stall = j.at("refined_since_stall").get<bool>();
  for (const char t : j.at("tried_initial_pairs").get<std::string>()) {
    c.tried_initial_pairs.push_back(t == '1' ? 1 : 0);
  }
  c.random_state = j.at("random_state").get<std::string>();
  c.loop_random_state = j.at("loop_random_state").get<std::string>();
  c.loop_window = GetInts<image_t>(j.at("loop_window"));
  c.loop_cooldown = GetInt<int>(j.at("loop_cooldown"));
  c.report = MapperReportFromJson(j.at("report"));
  return c;
}

}  // namespace

nlohmann::json MapperCheckpointFingerprint(const MapperInput& input,
                                           const IncrementalMapperOptions& options) {
  return {{"input", InputDigest(input)}, {"options", OptionsJson(options)}};
}

void WriteMapperCheckpoint(const fs::path& path, const MapperCheckpoint& checkpoint,
                           const nlohmann::json& fingerprint) {
  ByteWriter body;
  for (const MapperCheckpoint::Model& model : checkpoint.kept) PutMappedState(body, model.state);
  if (checkpoint.growing) PutMappedState(body, checkpoint.growing->state);
  WriteCheckpointFile(path, kFormat, HeaderJson(checkpoint), fingerprint, body.Bytes());
}

std::optional<MapperCheckpoint> ReadMapperCheckpoint(const fs::path& path,
                                                     const nlohmann::json& fingerprint) {
  MapperCheckpoint checkpoint;
  const bool read = ReadCheckpointFile(
      path, kFormat, fingerprint, [&](const nlohmann::json& header, ByteReader& body) {
        checkpoint = CheckpointFromHeader(header);
        for (MapperCheckpoint::Model& model : checkpoint.kept) model.state = GetMappedState(body);
        if (checkpoint.growing) checkpoint.growing->state = GetMappedState(body);
      });
  if (!read) return std::nullopt;
  return checkpoint;
}

MapperCheckpointFile::MapperCheckpointFile(std::filesystem::path path, const MapperInput& input,
                                           const IncrementalMapperOptions& options,
                                           double interval_seconds)
    : path_(std::move(path)),
      fingerprint_(MapperCheckpointFingerprint(input, options)),
      resume_(ReadMapperCheckpoint(path_, fingerprint_)) {
  if (resume_) checkpointing_.resume = &*resume_;
  checkpointing_.interval_seconds = interval_seconds;
  checkpointing_.save = [this](const MapperCheckpoint& checkpoint) {
    WriteMapperCheckpoint(path_, checkpoint, fingerprint_);
  };
}

}  // namespace loopsfm
