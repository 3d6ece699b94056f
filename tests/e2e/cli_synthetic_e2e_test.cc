// The whole CLI on a synthetic video with exact ground truth: `loopsfm synth` renders a
// cylinder circled a little more than once, `loopsfm reconstruct` turns the video into a
// model, and the test scores the model and checks every output file.
//
// Tolerances, from the figures measured when the test was written (36 frames, 480x360,
// known intrinsics): ATE 0.033 % of the path length, rotation error mean 0.20 deg (max
// 0.35), 36 / 36 frames registered, ~3300 points. The bounds are about 3x above those.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <regex>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cli_test_util.h"
#include "loopsfm/eval/trajectory_metrics.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/storage/colmap_model.h"

namespace loopsfm::e2e {
namespace {

constexpr int kNumFrames = 36;
constexpr int kWidth = 480;
constexpr int kHeight = 360;
// Tolerances (see the top of the file).
constexpr double kMinFractionRegistered = 0.95;
constexpr double kMaxAteFractionOfPath = 0.001;
constexpr double kMaxRotationErrorMeanDeg = 0.6;
constexpr size_t kMinPlyVertices = 1000;

struct SyntheticRun {
  fs::path dir;
  fs::path scene;  // video.mp4, intrinsics.txt, groundtruth.txt
  fs::path out;    // reconstruct's output folder
  CommandResult reconstruct;
  double reconstruct_seconds = 0.0;
  std::string error;
};

class CliSyntheticTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    run_ = new SyntheticRun;
    SyntheticRun& r = *run_;
    r.dir = fs::temp_directory_path() / fmt::format("loopsfm_e2e_{}_synthetic", getpid());
    fs::remove_all(r.dir);
    fs::create_directories(r.dir);
    r.scene = r.dir / "scene";
    r.out = r.dir / "out";
    const CommandResult synth = RunLoopsfm(
        {"-q", "synth", "cylinder", "--video", "-o", r.scene.string(), "--frames",
         std::to_string(kNumFrames), "--width", std::to_string(kWidth), "--height",
         std::to_string(kHeight)});
    if (synth.exit_code != 0) {
      std::ostringstream message;
      message << "rendering the synthetic video failed:" << synth;
      r.error = message.str();
      return;
    }
    const auto start = std::chrono::steady_clock::now();
    // Every frame (--every 1): the tests below check each frame's name, registration and
    // pose (adaptive keyframes have tests of their own, cli_keyframes_e2e_test).
    r.reconstruct = RunLoopsfm({"reconstruct", (r.scene / "video.mp4").string(), "--intrinsics",
                                (r.scene / "intrinsics.txt").string(), "-o", r.out.string(),
                                "--text", "--every", "1"});
    r.reconstruct_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << "[ info     ] reconstruct took " << r.reconstruct_seconds << " s\n";
  }

  static void TearDownTestSuite() {
    if (run_ != nullptr && !::testing::UnitTest::GetInstance()->Failed()) {
      std::error_code ignored;
      fs::remove_all(run_->dir, ignored);
    }
    delete run_;
    run_ = nullptr;
  }

  void SetUp() override {
    ASSERT_TRUE(run_->error.empty()) << run_->error;
    ASSERT_EQ(run_->reconstruct.exit_code, 0) << run_->reconstruct;
  }

  static fs::path Model0() { return run_->out / "sparse" / "0"; }
  static std::vector<TrajectoryEntry> GroundTruth() {
    return ReadTrajectoryFile(run_->scene / "groundtruth.txt");
  }

  static SyntheticRun* run_;
};

SyntheticRun* CliSyntheticTest::run_ = nullptr;

TEST_F(CliSyntheticTest, OneAccurateModelWithAllFrames) {
  std::vector<fs::path> models;
  for (const auto& entry : fs::directory_iterator(run_->out / "sparse")) {
    if (entry.is_directory()) models.push_back(entry.path());
  }
  EXPECT_EQ(models.size(), 1u) << "the scene broke into several models" << run_->reconstruct;

  const Reconstruction model = ReadColmapModel(Model0());
  EXPECT_GE(static_cast<double>(model.NumRegImages()), kMinFractionRegistered * kNumFrames)
      << run_->reconstruct;

  const TrajectoryMetrics metrics = EvaluateTrajectory(model, GroundTruth());
  ASSERT_TRUE(metrics.aligned) << metrics.explanation;
  EXPECT_EQ(metrics.num_gt_frames, static_cast<size_t>(kNumFrames));
  EXPECT_EQ(metrics.num_matched, model.NumRegImages()) << "registered frames missing in the "
                                                          "ground truth (names do not join)";
  EXPECT_GE(metrics.fraction_registered, kMinFractionRegistered);
  EXPECT_LT(metrics.ate_fraction_of_path, kMaxAteFractionOfPath);
  EXPECT_LT(metrics.rotation_error_mean_deg, kMaxRotationErrorMeanDeg);
  std::cout << fmt::format(
      "[ info     ] {} / {} registered, {} points, ATE {:.5f} ({:.4f} % of path {:.3f}), "
      "rotation error mean {:.3f} deg, max {:.3f} deg\n",
      metrics.num_matched, metrics.num_gt_frames, model.NumPoints3D(), metrics.ate_rmse,
      100.0 * metrics.ate_fraction_of_path, metrics.gt_path_length,
      metrics.rotation_error_mean_deg, metrics.rotation_error_max_deg);

  // --text wrote the same model as text.
  const Reconstruction text = ReadColmapModelText(Model0());
  EXPECT_EQ(text.NumRegImages(), model.NumRegImages());
  EXPECT_EQ(text.NumPoints3D(), model.NumPoints3D());
}

TEST_F(CliSyntheticTest, WritesModelPointCloudAndTrajectory) {
  for (const char* name : {"cameras.bin", "images.bin", "points3D.bin"}) {
    EXPECT_TRUE(fs::is_regular_file(Model0() / name)) << name;
    EXPECT_GT(fs::file_size(Model0() / name), 8u) << name;
  }
  EXPECT_TRUE(fs::is_regular_file(run_->out / "database.db"));
  const Reconstruction model = ReadColmapModel(Model0());

  // points.ply: binary little-endian, one vertex per 3D point of model 0, all finite.
  const std::string ply = ReadFileBytes(run_->out / "points.ply");
  const size_t header_end = ply.find("end_header\n");
  ASSERT_NE(header_end, std::string::npos) << "points.ply has no PLY header";
  const std::string header = ply.substr(0, header_end);
  EXPECT_EQ(header.rfind("ply\n", 0), 0u);
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos) << header;
  std::smatch vertex;
  ASSERT_TRUE(std::regex_search(header, vertex, std::regex("element vertex (\\d+)"))) << header;
  const size_t num_vertices = std::stoul(vertex[1]);
  EXPECT_GT(num_vertices, kMinPlyVertices);
  EXPECT_EQ(num_vertices, model.NumPoints3D());
  const std::string expected_properties =
      "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
      "property uchar green\nproperty uchar blue\n";
  ASSERT_NE(header.find(expected_properties), std::string::npos) << header;
  constexpr size_t kVertexBytes = 3 * sizeof(float) + 3;
  const size_t data_begin = header_end + std::string("end_header\n").size();
  ASSERT_EQ(ply.size(), data_begin + num_vertices * kVertexBytes) << "points.ply size";
  Eigen::Vector3d ply_sum = Eigen::Vector3d::Zero(), model_sum = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < num_vertices; ++i) {
    float xyz[3];
    std::memcpy(xyz, ply.data() + data_begin + i * kVertexBytes, sizeof(xyz));
    ASSERT_TRUE(std::isfinite(xyz[0]) && std::isfinite(xyz[1]) && std::isfinite(xyz[2]));
    ply_sum += Eigen::Vector3f(xyz[0], xyz[1], xyz[2]).cast<double>();
  }
  for (const auto& [id, point] : model.Points3D()) model_sum += point.xyz;
  EXPECT_LT((ply_sum - model_sum).norm() / num_vertices, 1e-4)
      << "points.ply holds other points than the model";

  // trajectory.txt: one line per registered frame, the model's world_from_cam poses.
  EXPECT_EQ(DataLines(run_->out / "trajectory.txt").size(), model.NumRegImages());
  const std::vector<TrajectoryEntry> trajectory = ReadTrajectoryFile(run_->out / "trajectory.txt");
  ASSERT_EQ(trajectory.size(), model.NumRegImages());
  std::map<std::string, Rigid3d> model_poses;
  for (const auto& [id, image] : model.Images()) {
    if (image.registered) model_poses[image.name] = image.cam_from_world.Inverse();
  }
  for (size_t i = 0; i < trajectory.size(); ++i) {
    const TrajectoryEntry& entry = trajectory[i];
    if (i > 0) {
      EXPECT_LT(trajectory[i - 1].name, entry.name) << "not sorted by name";
    }
    const auto it = model_poses.find(entry.name);
    ASSERT_NE(it, model_poses.end()) << entry.name << " is not a registered image";
    EXPECT_LT((entry.world_from_cam.translation - it->second.translation).norm(), 1e-6)
        << entry.name;
    EXPECT_LT(entry.world_from_cam.rotation.angularDistance(it->second.rotation), 1e-6)
        << entry.name;
  }
}

TEST_F(CliSyntheticTest, EvalJsonAgreesWithTheLibrary) {
  const CommandResult eval = RunShell(
      ShellQuote(LoopsfmBinary().string()) + " eval " + ShellQuote(Model0().string()) + " " +
      ShellQuote((run_->scene / "groundtruth.txt").string()) + " --json 2>/dev/null");
  ASSERT_EQ(eval.exit_code, 0) << eval;
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(eval.output);
  } catch (const nlohmann::json::exception& e) {
    FAIL() << "eval --json printed something that is not JSON: " << e.what() << eval;
  }
  const TrajectoryMetrics metrics = EvaluateTrajectory(ReadColmapModel(Model0()), GroundTruth());
  ASSERT_TRUE(metrics.aligned);
  EXPECT_EQ(json.at("aligned").get<bool>(), true);
  EXPECT_EQ(json.at("num_gt_frames").get<size_t>(), metrics.num_gt_frames);
  EXPECT_EQ(json.at("num_matched").get<size_t>(), metrics.num_matched);
  auto expect_same = [&](const char* key, double value) {
    ASSERT_TRUE(json.contains(key) && json.at(key).is_number()) << key << "\n" << json.dump(2);
    EXPECT_NEAR(json.at(key).get<double>(), value, 1e-9 * std::max(1.0, std::abs(value))) << key;
  };
  expect_same("fraction_registered", metrics.fraction_registered);
  expect_same("gt_path_length", metrics.gt_path_length);
  expect_same("ate_rmse", metrics.ate_rmse);
  expect_same("ate_fraction_of_path", metrics.ate_fraction_of_path);
  expect_same("rotation_error_mean_deg", metrics.rotation_error_mean_deg);
  expect_same("rotation_error_max_deg", metrics.rotation_error_max_deg);
}

// `eval --rpe-step N` scores the relative poses of ground-truth frames N apart, as the library
// does with that step, in the text and in the JSON.
TEST_F(CliSyntheticTest, EvalRelativePoseErrorAtAGivenStep) {
  const std::string base = ShellQuote(LoopsfmBinary().string()) + " eval " +
                           ShellQuote(Model0().string()) + " " +
                           ShellQuote((run_->scene / "groundtruth.txt").string()) +
                           " --rpe-step 5";
  TrajectoryEvalOptions options;
  options.rpe_step = 5;
  const TrajectoryMetrics metrics =
      EvaluateTrajectory(ReadColmapModel(Model0()), GroundTruth(), options);
  ASSERT_TRUE(metrics.rpe && metrics.rpe->num_pairs > 0);
  const CommandResult json_run = RunShell(base + " --json 2>/dev/null");
  ASSERT_EQ(json_run.exit_code, 0) << json_run;
  const nlohmann::json rpe = nlohmann::json::parse(json_run.output).at("rpe");
  EXPECT_EQ(rpe.at("step").get<int>(), 5);
  EXPECT_EQ(rpe.at("num_pairs").get<size_t>(), metrics.rpe->num_pairs);
  EXPECT_NEAR(rpe.at("rotation_mean_deg").get<double>(), metrics.rpe->rotation_mean_deg, 1e-9);
  const CommandResult text = RunShell(base);
  ASSERT_EQ(text.exit_code, 0) << text;
  EXPECT_NE(text.output.find("relative pose error " + std::to_string(metrics.rpe->num_pairs) +
                             " pairs 5 frames apart"),
            std::string::npos)
      << text;
  EXPECT_EQ(RunShell(base + " --rpe-step -1").exit_code, 2);
}

// Loop closing is on by default, so the run lists the frames it tied together (none need
// tying on this render: the file may hold only its header). `eval --plot-links` draws such
// links between the model's frames, and refuses links that join none of them.
TEST_F(CliSyntheticTest, LoopLinksAreWrittenAndPlotted) {
  ASSERT_TRUE(fs::exists(run_->out / "loop_links.txt")) << run_->reconstruct;
  EXPECT_NO_THROW(ReadLoopLinksFile(run_->out / "loop_links.txt"));

  const Reconstruction model = ReadColmapModel(Model0());
  std::vector<std::string> names;
  for (const auto& [id, image] : model.Images()) {
    if (image.registered) names.push_back(image.name);
  }
  std::sort(names.begin(), names.end());
  ASSERT_GE(names.size(), 10u);
  const fs::path links = run_->dir / "links.txt";
  WriteLoopLinksFile(links, {{"split", names.front(), names[names.size() / 2], 40},
                             {"posegraph", names[1], names.back(), 12}});
  const std::string gt = (run_->scene / "groundtruth.txt").string();
  const fs::path plain = run_->dir / "plain.png", linked = run_->dir / "linked.png";
  const CommandResult without =
      RunLoopsfm({"eval", Model0().string(), gt, "--plot", plain.string()});
  ASSERT_EQ(without.exit_code, 0) << without;
  const CommandResult with = RunLoopsfm(
      {"eval", Model0().string(), gt, "--plot", linked.string(), "--plot-links", links.string()});
  ASSERT_EQ(with.exit_code, 0) << with;
  ASSERT_TRUE(fs::exists(linked));
  auto bytes = [](const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  EXPECT_NE(bytes(linked), bytes(plain)) << "the links changed nothing drawn";

  const fs::path foreign = run_->dir / "foreign_links.txt";
  WriteLoopLinksFile(foreign, {{"split", "not_a_frame.png", "nor_this.png", 5}});
  const CommandResult refused = RunLoopsfm({"eval", Model0().string(), gt, "--plot",
                                            linked.string(), "--plot-links", foreign.string()});
  EXPECT_EQ(refused.exit_code, 2) << refused;
  EXPECT_NE(refused.output.find("joins two frames"), std::string::npos) << refused;
  const CommandResult no_plot =
      RunLoopsfm({"eval", Model0().string(), gt, "--plot-links", links.string()});
  EXPECT_EQ(no_plot.exit_code, 2) << no_plot;
  EXPECT_NE(no_plot.output.find("--plot-links needs --plot"), std::string::npos) << no_plot;
}

TEST_F(CliSyntheticTest, DatabaseNamesVideoFramesByIndex) {
  const Database database = Database::Open((run_->out / "database.db").string());
  const std::vector<Frame> frames = database.ReadFrames();
  ASSERT_EQ(frames.size(), static_cast<size_t>(kNumFrames));
  std::set<std::string> names;
  for (const Frame& frame : frames) {
    names.insert(frame.name);
    const std::optional<FrameOrigin> origin = database.ReadFrameOrigin(frame.image_id);
    ASSERT_TRUE(origin.has_value()) << frame.name;
    EXPECT_EQ(frame.name, fmt::format("frame_{:06d}.png", origin->source_index));
  }
  std::set<std::string> expected;
  for (int i = 0; i < kNumFrames; ++i) expected.insert(fmt::format("frame_{:06d}.png", i));
  EXPECT_EQ(names, expected);

  // One camera, the one of --intrinsics.
  const std::vector<Camera> cameras = database.ReadCameras();
  ASSERT_EQ(cameras.size(), 1u);
  const Camera given = ReadIntrinsicsFile(run_->scene / "intrinsics.txt");
  EXPECT_TRUE(cameras[0].SameIntrinsics(given))
      << cameras[0].ModelName() << " " << cameras[0].width << "x" << cameras[0].height;
}

// Sequential pairing with a small overlap never pairs the first frames with the last ones
// of the loop, although they see the same part of the cylinder; vocabulary-tree guided
// matching on the same database verifies such a pair without trying every pair. (With the
// default of 5 loop partners per frame, the band of loop pairs is thinned: the loop is
// closed by e.g. (0, 33) and (2, 35), not necessarily by (0, 35) itself.)
// The global mapper on the same database: every frame, as accurate as the incremental
// mapper's bounds, and the summary names its stages. The incremental mapper's options are
// refused with it.
TEST_F(CliSyntheticTest, GlobalMapperMapsTheLoopWhole) {
  TempDir tmp;
  fs::copy_file(run_->out / "database.db", tmp / "database.db");
  const std::vector<std::string> args = {"reconstruct", (run_->scene / "video.mp4").string(),
                                         "--intrinsics", (run_->scene / "intrinsics.txt").string(),
                                         "-o", tmp.path().string(), "--every", "1",
                                         "--mapper", "global", "--export", "colmap,report"};
  const CommandResult global = RunLoopsfm(args);
  ASSERT_EQ(global.exit_code, 0) << global;
  EXPECT_NE(global.output.find("global positioning"), std::string::npos) << global;
  EXPECT_NE(global.output.find("time map: positions"), std::string::npos) << global;
  const Reconstruction model = ReadColmapModel(tmp / "sparse" / "0");
  const TrajectoryMetrics metrics = EvaluateTrajectory(model, GroundTruth());
  ASSERT_TRUE(metrics.aligned) << metrics.explanation;
  EXPECT_GE(metrics.fraction_registered, kMinFractionRegistered);
  EXPECT_LT(metrics.ate_fraction_of_path, kMaxAteFractionOfPath);
  EXPECT_LT(metrics.rotation_error_mean_deg, kMaxRotationErrorMeanDeg);
  std::cout << fmt::format("[ info     ] global mapper: {} / {} registered, ATE {:.4f} % of the "
                           "path, rotation error mean {:.3f} deg\n",
                           metrics.num_matched, metrics.num_gt_frames,
                           100.0 * metrics.ate_fraction_of_path, metrics.rotation_error_mean_deg);
  std::ifstream report(tmp / "report.html");
  const std::string html((std::istreambuf_iterator<char>(report)), std::istreambuf_iterator<char>());
  EXPECT_NE(html.find("\"mapper\":\"global\""), std::string::npos);
  EXPECT_EQ(global.output.find("set aside"), std::string::npos)
      << "a good global model was taken for a doubtful one" << global;

  std::vector<std::string> with_loop_closing = args;
  with_loop_closing.insert(with_loop_closing.end(), {"--loop-closing", "split"});
  const CommandResult refused = RunLoopsfm(with_loop_closing);
  EXPECT_EQ(refused.exit_code, 2) << refused;
  EXPECT_NE(refused.output.find("--loop-closing"), std::string::npos) << refused;
  std::vector<std::string> keep_without_global = args;
  keep_without_global.erase(std::find(keep_without_global.begin(), keep_without_global.end(),
                                      "--mapper"),
                            std::find(keep_without_global.begin(), keep_without_global.end(),
                                      "--export"));
  keep_without_global.push_back("--keep-global-model");
  const CommandResult keep_refused = RunLoopsfm(keep_without_global);
  EXPECT_EQ(keep_refused.exit_code, 2) << keep_refused;
  EXPECT_NE(keep_refused.output.find("add --mapper global"), std::string::npos) << keep_refused;
}

// The same database mapped in three segments (the loop's two ends fall in the first and the
// last): merged into one model, as accurate as the bounds of the whole-video run, the summary
// naming each segment; a rerun takes every segment from its checkpoint. Flags that do not go
// with segments are refused before anything runs.
TEST_F(CliSyntheticTest, SegmentsMergeIntoOneModelOfTheLoop) {
  TempDir tmp;
  fs::copy_file(run_->out / "database.db", tmp / "database.db");
  const std::vector<std::string> args = {"reconstruct", (run_->scene / "video.mp4").string(),
                                         "--intrinsics", (run_->scene / "intrinsics.txt").string(),
                                         "-o", tmp.path().string(), "--every", "1",
                                         "--segments", "3", "--segment-overlap", "6",
                                         "--export", "colmap,report"};
  const CommandResult segmented = RunLoopsfm(args);
  ASSERT_EQ(segmented.exit_code, 0) << segmented;
  EXPECT_NE(segmented.output.find("segment 2"), std::string::npos) << segmented;
  EXPECT_NE(segmented.output.find("time map: merge"), std::string::npos) << segmented;
  EXPECT_FALSE(fs::exists(tmp / "sparse" / "1")) << "the segments did not merge" << segmented;
  const Reconstruction model = ReadColmapModel(tmp / "sparse" / "0");
  const TrajectoryMetrics metrics = EvaluateTrajectory(model, GroundTruth());
  ASSERT_TRUE(metrics.aligned) << metrics.explanation;
  EXPECT_GE(metrics.fraction_registered, kMinFractionRegistered);
  EXPECT_LT(metrics.ate_fraction_of_path, kMaxAteFractionOfPath);
  EXPECT_LT(metrics.rotation_error_mean_deg, kMaxRotationErrorMeanDeg);
  EXPECT_TRUE(fs::exists(tmp / "segments" / "segment_2.bin")) << segmented;
  std::ifstream report(tmp / "report.html");
  const std::string html((std::istreambuf_iterator<char>(report)), std::istreambuf_iterator<char>());
  EXPECT_NE(html.find("\"mapper\":\"incremental, 3 segments\""), std::string::npos);
  const CommandResult rerun = RunLoopsfm(args);
  ASSERT_EQ(rerun.exit_code, 0) << rerun;
  for (int k = 0; k < 3; ++k) {  // the summary's line of each segment
    EXPECT_TRUE(std::regex_search(rerun.output,
                                  std::regex(fmt::format("  segment {} +frames [^\\n]* s \\(from "
                                                         "its checkpoint\\)",
                                                         k))))
        << rerun;
  }
  std::cout << fmt::format("[ info     ] 3 segments: {} / {} registered, ATE {:.4f} % of the "
                           "path, rotation error mean {:.3f} deg\n",
                           metrics.num_matched, metrics.num_gt_frames,
                           100.0 * metrics.ate_fraction_of_path, metrics.rotation_error_mean_deg);

  std::vector<std::string> refused_args = args;
  refused_args.push_back("--withhold-loop-pairs");
  const CommandResult refused = RunLoopsfm(refused_args);
  EXPECT_EQ(refused.exit_code, 2) << refused;
  EXPECT_NE(refused.output.find("--segments"), std::string::npos) << refused;

  // The global mapper on each segment: the segments merge into one model of the loop too.
  TempDir global_tmp("global");
  fs::copy_file(run_->out / "database.db", global_tmp / "database.db");
  std::vector<std::string> global_args = args;
  global_args[std::find(args.begin(), args.end(), "-o") - args.begin() + 1] =
      global_tmp.path().string();
  global_args.insert(global_args.end(), {"--mapper", "global"});
  const CommandResult global = RunLoopsfm(global_args);
  ASSERT_EQ(global.exit_code, 0) << global;
  EXPECT_FALSE(fs::exists(global_tmp / "sparse" / "1")) << "the segments did not merge" << global;
  const TrajectoryMetrics global_metrics =
      EvaluateTrajectory(ReadColmapModel(global_tmp / "sparse" / "0"), GroundTruth());
  ASSERT_TRUE(global_metrics.aligned) << global_metrics.explanation;
  EXPECT_GE(global_metrics.fraction_registered, kMinFractionRegistered);
  EXPECT_LT(global_metrics.ate_fraction_of_path, kMaxAteFractionOfPath);
  EXPECT_FALSE(fs::exists(global_tmp / "segments")) << "global segments have no checkpoints";
  std::ifstream global_report(global_tmp / "report.html");
  const std::string global_html((std::istreambuf_iterator<char>(global_report)),
                                std::istreambuf_iterator<char>());
  EXPECT_NE(global_html.find("\"mapper\":\"global, 3 segments\""), std::string::npos);
  std::cout << fmt::format("[ info     ] 3 segments, global mapper: {} / {} registered, ATE "
                           "{:.4f} % of the path\n",
                           global_metrics.num_matched, global_metrics.num_gt_frames,
                           100.0 * global_metrics.ate_fraction_of_path);
  const CommandResult overlap_alone = RunLoopsfm(
      {"reconstruct", (run_->scene / "video.mp4").string(), "-o", tmp.path().string(),
       "--segment-overlap", "6"});
  EXPECT_EQ(overlap_alone.exit_code, 2) << overlap_alone;
}

TEST_F(CliSyntheticTest, SequentialPairsLeaveTheLoopOpenVocabTreeClosesIt) {
  TempDir tmp;
  const fs::path db = tmp / "database.db";
  const CommandResult extract =
      RunLoopsfm({"-q", "extract", (run_->scene / "video.mp4").string(), "-d", db.string(),
                  "--intrinsics", (run_->scene / "intrinsics.txt").string(), "--every", "1"});
  ASSERT_EQ(extract.exit_code, 0) << extract;
  const CommandResult sequential =
      RunLoopsfm({"-q", "match", "-d", db.string(), "--pairs", "sequential", "--overlap", "3"});
  ASSERT_EQ(sequential.exit_code, 0) << sequential;

  // Frame index of each image id; a loop pair joins one of the first and one of the last
  // kEnd frames.
  constexpr int kEnd = 3;
  std::map<image_t, int> index_of;
  {
    const Database database = Database::Open(db.string());
    for (int i = 0; i < kNumFrames; ++i) {
      const std::optional<Frame> f = database.FindFrame(fmt::format("frame_{:06d}.png", i));
      ASSERT_TRUE(f.has_value());
      index_of[f->image_id] = i;
    }
  }
  auto is_loop_pair = [&](const ImagePair& pair) {
    const int a = std::min(index_of.at(pair.image_id1), index_of.at(pair.image_id2));
    const int b = std::max(index_of.at(pair.image_id1), index_of.at(pair.image_id2));
    return a < kEnd && b >= kNumFrames - kEnd;
  };
  auto best_loop_pair_inliers = [&](const Database& database) {
    int best = 0;
    for (const VerifiedPair& pair : database.ReadVerifiedPairs()) {
      if (is_loop_pair(pair.pair)) best = std::max(best, pair.num_inliers);
    }
    return best;
  };
  {
    const Database database = Database::Open(db.string());
    EXPECT_GT(database.NumVerifiedPairs(), static_cast<size_t>(kNumFrames - 1))
        << "neighbouring frames should verify";
    EXPECT_EQ(best_loop_pair_inliers(database), 0) << "sequential pairing verified a loop pair";
  }

  // Vocabulary-tree loop detection on the same database (sequential pairs are resumed)
  // finds a loop pair without trying every pair.
  const fs::path similarity = tmp / "similarity.txt";
  const CommandResult guided =
      RunLoopsfm({"-q", "match", "-d", db.string(), "--pairs", "vocabtree", "--overlap", "3",
                  "--similarity-out", similarity.string()});
  ASSERT_EQ(guided.exit_code, 0) << guided;
  {
    // The similarity streamed row by row: a line of names, then n symmetric rows of n scores
    // with each frame's score with itself (1 up to rounding) on the diagonal.
    std::ifstream in(similarity);
    std::string line;
    ASSERT_TRUE(std::getline(in, line));
    std::vector<std::vector<double>> rows;
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      rows.emplace_back(std::istream_iterator<double>(fields), std::istream_iterator<double>());
    }
    ASSERT_EQ(rows.size(), static_cast<size_t>(kNumFrames));
    for (size_t i = 0; i < rows.size(); ++i) {
      ASSERT_EQ(rows[i].size(), rows.size()) << "row " << i;
      EXPECT_NEAR(rows[i][i], 1.0, 1e-3) << "row " << i;
      for (size_t j = 0; j < i; ++j) EXPECT_NEAR(rows[i][j], rows[j][i], 1e-5);
    }
  }
  int loop_inliers = 0;
  {
    const Database database = Database::Open(db.string());
    loop_inliers = best_loop_pair_inliers(database);
    EXPECT_GE(loop_inliers, 50) << "vocabtree should verify a loop pair";
    const size_t all_pairs = kNumFrames * (kNumFrames - 1) / 2;
    EXPECT_LT(database.NumMatchedPairs(), all_pairs) << "vocabtree tried every pair";
    std::cout << "[ info     ] vocabtree: best loop pair " << loop_inliers << " inliers, "
              << database.NumMatchedPairs() << " of " << all_pairs << " pairs tried\n";
  }
  EXPECT_TRUE(fs::exists(tmp / "database_similarity.png"));
  EXPECT_TRUE(fs::exists(tmp / "database_matches.png"));

  // Exhaustive matching confirms the first and last frames overlap, and finds no loop pair
  // much stronger than the one vocabtree verified.
  const CommandResult exhaustive =
      RunLoopsfm({"-q", "match", "-d", db.string(), "--pairs", "exhaustive"});
  ASSERT_EQ(exhaustive.exit_code, 0) << exhaustive;
  const Database database = Database::Open(db.string());
  EXPECT_LE(best_loop_pair_inliers(database), 2 * loop_inliers);
}

// The build links mimalloc where libmimalloc-dev is installed (docs/scale: the mapping's bundles
// run faster in its heap). The binary says which allocator actually serves malloc, so a link
// that leaves glibc's malloc in charge fails here.
TEST(CliVersion, NamesTheAllocatorThatServesMalloc) {
  const CommandResult result = RunLoopsfm({"--version"});
  ASSERT_EQ(result.exit_code, 0) << result;
#ifdef LOOPSFM_EXPECT_MIMALLOC
  EXPECT_NE(result.output.find("memory allocator: mimalloc 2."), std::string::npos) << result;
#else
  EXPECT_NE(result.output.find("memory allocator: the C library's malloc"), std::string::npos)
      << result;
#endif
}

}  // namespace
}  // namespace loopsfm::e2e
