// Writes the seed corpus of the fuzz targets with loopsfm's own writers: a few small valid
// files of each format and edge cases cut from them (empty, truncated, one byte flipped).
// Run once to (re)create tests/fuzz/corpus/<target>/seed_*; the reproducers of findings
// (crash_*) and hand-made edge cases (edge_*) beside them are not touched:
//   cmake --build BUILD --target write_seed_corpus && BUILD/tests/fuzz/write_seed_corpus tests/fuzz/corpus

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "database_fuzz_input.h"
#include "fuzz_util.h"
#include "loopsfm/math/random.h"
#include "loopsfm/pipeline/mapper_checkpoint.h"
#include "loopsfm/retrieval/vocabulary_tree.h"
#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/storage/colmap_model.h"
#include "mapper_checkpoint_fuzz_input.h"

namespace loopsfm::fuzz {
namespace {

namespace fs = std::filesystem;

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

class CorpusWriter {
 public:
  CorpusWriter(const fs::path& root, const std::string& target) : dir_(root / target) {
    fs::create_directories(dir_);
    for (const auto& entry : fs::directory_iterator(dir_)) {
      if (entry.path().filename().string().starts_with("seed_")) fs::remove(entry.path());
    }
  }
  void Add(const std::string& name, const std::string& bytes) {
    std::ofstream(dir_ / ("seed_" + name), std::ios::binary) << bytes;
  }
  // The valid bytes and edge cases cut from them.
  void AddWithEdgeCases(const std::string& name, const std::string& bytes) {
    Add(name, bytes);
    Add(name + "_half", bytes.substr(0, bytes.size() / 2));
    std::string flipped = bytes;
    if (!flipped.empty()) flipped[flipped.size() / 3] ^= 0x5a;
    Add(name + "_flipped", flipped);
  }

 private:
  fs::path dir_;
};

Reconstruction SmallScene() {
  Reconstruction rec;
  rec.AddCamera({.camera_id = 1,
                 .model_id = CameraModelId::kSimpleRadial,
                 .width = 64,
                 .height = 48,
                 .params = {50.5, 32, 24, 0.01}});
  for (image_t id = 1; id <= 3; ++id) {
    Image image;
    image.image_id = id;
    image.camera_id = 1;
    image.name = "frame_" + std::to_string(id) + ".png";
    image.cam_from_world.translation = Eigen::Vector3d(-0.1 * id, 0, 0);
    for (int k = 0; k < 3; ++k) image.points2D.push_back({Eigen::Vector2d(10 + k, 20 - id)});
    rec.AddImage(image);
    rec.RegisterImage(id);
  }
  for (point2D_t k = 0; k < 2; ++k) {
    Track track;
    for (image_t id = 1; id <= 3; ++id) track.elements.push_back({id, k});
    rec.AddPoint3D(Eigen::Vector3d(k, 0.5, 4), track, Eigen::Matrix<uint8_t, 3, 1>(10, 200, 30));
  }
  return rec;
}

// The model's three files joined as the colmap_*_fuzz targets split them.
std::string JoinedModel(const fs::path& dir, const std::string& extension) {
  std::string joined;
  for (const char* name : {"cameras", "images", "points3D"}) {
    if (!joined.empty()) joined += kFileSeparator;
    joined += ReadBytes(dir / (name + extension));
  }
  return joined;
}

void WriteModels(const fs::path& root) {
  const fs::path dir = ScratchDir() / "model";
  CorpusWriter binary(root, "colmap_binary");
  CorpusWriter text(root, "colmap_text");
  WriteColmapModelBinary(dir / "empty", Reconstruction());
  WriteColmapModelText(dir / "empty", Reconstruction());
  binary.Add("empty_model", JoinedModel(dir / "empty", ".bin"));
  text.Add("empty_model", JoinedModel(dir / "empty", ".txt"));
  WriteColmapModelBinary(dir / "small", SmallScene());
  WriteColmapModelText(dir / "small", SmallScene());
  binary.AddWithEdgeCases("small_model", JoinedModel(dir / "small", ".bin"));
  text.AddWithEdgeCases("small_model", JoinedModel(dir / "small", ".txt"));
}

void WriteDatasetFiles(const fs::path& root) {
  CorpusWriter intrinsics(root, "intrinsics");
  for (const CameraModelId id : kCameraModelIds) {
    Camera camera = Camera::GuessFromImageSize(640, 480, id);
    camera.params.back() += 0.015;  // a distortion term (or cy) that is not round
    WriteIntrinsicsFile(ScratchDir() / "intrinsics.txt", camera);
    intrinsics.Add(std::string(CameraModelName(id)), ReadBytes(ScratchDir() / "intrinsics.txt"));
  }
  intrinsics.Add("empty", "");
  CorpusWriter trajectory(root, "trajectory");
  std::vector<TrajectoryEntry> entries;
  for (int i = 0; i < 3; ++i) {
    entries.push_back({"frame_" + std::to_string(i) + ".png",
                       Rigid3d(Eigen::Quaterniond(1, 0.1 * i, 0, 0).normalized(),
                               Eigen::Vector3d(i, 0.5, -0.25 * i))});
  }
  WriteTrajectoryFile(ScratchDir() / "trajectory.txt", entries);
  trajectory.AddWithEdgeCases("three_frames", ReadBytes(ScratchDir() / "trajectory.txt"));
  trajectory.Add("empty", "");
}

void WriteVocabularyTrees(const fs::path& root) {
  CorpusWriter writer(root, "vocabulary_tree");
  Random random(7);
  FeatureDescriptors descriptors(24, kDescriptorDim);
  for (int i = 0; i < descriptors.size(); ++i) {
    descriptors.data()[i] = static_cast<uint8_t>(random.UniformInt(0, 255));
  }
  VocabTreeOptions options;
  options.branching = 3;
  options.depth = 2;
  const fs::path path = ScratchDir() / "tree.bin";
  VocabularyTree::Train(descriptors, options, random).Save(path);
  writer.AddWithEdgeCases("branching3_depth2", ReadBytes(path));
  writer.Add("empty", "");
}

std::string Bytes(const void* data, size_t size) {
  return {static_cast<const char*>(data), size};
}

void WriteDatabaseRows(const fs::path& root) {
  CorpusWriter writer(root, "database_blob");
  using Row = DatabaseFuzzRow;
  const double params[4] = {500, 320, 240, 0.01};
  writer.Add("camera", Row{Row::kCameras, {2, 640, 480, 1}, {}, Bytes(params, sizeof(params))}.Encode());
  const float keypoints[2][6] = {{1, 2, 1, 0, 0, 1}, {3.5, 4, 2, 0.5, -0.5, 2}};
  writer.Add("keypoints6", Row{Row::kKeypoints, {2, 6}, {}, Bytes(keypoints, sizeof(keypoints))}.Encode());
  writer.Add("keypoints4", Row{Row::kKeypoints, {3, 4}, {}, Bytes(keypoints, 48)}.Encode());
  writer.Add("keypoints2", Row{Row::kKeypoints, {2, 2}, {}, Bytes(keypoints, 16)}.Encode());
  writer.Add("descriptors", Row{Row::kDescriptors, {2, 128}, {}, std::string(256, '\x11')}.Encode());
  const uint32_t matches[3][2] = {{0, 1}, {1, 0}, {5, 7}};
  writer.Add("matches", Row{Row::kMatches, {3, 2}, {}, Bytes(matches, sizeof(matches))}.Encode());
  writer.Add("matches_empty", Row{Row::kMatches, {0, 2}, {}, ""}.Encode());
  const double m[9] = {0, -1, 0.5, 1, 0, -0.25, -0.5, 0.25, 0};
  const double qvec[4] = {1, 0, 0, 0}, tvec[3] = {1, 0, 0};
  writer.Add("two_view_geometry",
             Row{Row::kTwoViewGeometries,
                 {3, 2, 2},
                 {Bytes(m, sizeof(m)), Bytes(m, sizeof(m)), Bytes(m, sizeof(m)),
                  Bytes(qvec, sizeof(qvec)), Bytes(tvec, sizeof(tvec))},
                 Bytes(matches, sizeof(matches))}
                 .Encode());
  writer.Add("two_view_geometry_unset", Row{Row::kTwoViewGeometries, {0, 2, 0}, {}, ""}.Encode());
}

// Checkpoints with MapperCheckpointFuzzFingerprint(): mapping finished with one model kept,
// and mapping under way (a kept model, a growing one, and the mapper's state and report).
void WriteMapperCheckpoints(const fs::path& root) {
  CorpusWriter writer(root, "mapper_checkpoint");
  const fs::path path = ScratchDir() / "mapper_checkpoint.bin";
  const nlohmann::json fingerprint = MapperCheckpointFuzzFingerprint();
  MapperCheckpoint::Model kept;
  kept.state = SmallScene().SaveMapped();
  kept.gauge1 = 1;
  kept.gauge2 = 3;
  MapperCheckpoint finished;
  finished.finished = true;
  finished.kept.push_back(kept);
  finished.report.num_models = 1;
  finished.report.num_registered = 3;
  WriteMapperCheckpoint(path, finished, fingerprint);
  writer.AddWithEdgeCases("finished", ReadBytes(path));

  MapperCheckpoint growing;
  growing.kept.push_back(kept);
  growing.kept.back().merge_failures = 1;
  Reconstruction two_frames = SmallScene();
  two_frames.DeRegisterImage(3);
  growing.growing = MapperCheckpoint::Model{two_frames.SaveMapped(), 1, 2, 0};
  growing.failed_at = {{3, 2}};
  growing.ever_failed = {3};
  growing.last_global_size = 2;
  growing.refined_since_stall = true;
  growing.tried_initial_pairs = {1, 0, 1};
  // Short stand-ins for Random::State() (6 kB each, only text to this reader; the mapper
  // parses them when it resumes).
  growing.random_state = "7 1 2 3";
  growing.loop_random_state = "8 1 2 3";
  growing.loop_window = {1, 2};
  growing.loop_cooldown = 2;
  MapperReport& report = growing.report;
  report.num_registered = 5;
  report.num_init_trials = 2;
  report.num_local_ba_iterations = 40;
  report.seconds_local_ba = 0.25;
  report.loops_closed.push_back(
      {"frame_3.png", "frame_1.png", 12, 9, 0.5, 0.1, 2.0, 1.01, 4, 3, 0.125});
  report.path_before_loop_closing.push_back({"frame_1.png", Rigid3d()});
  report.registrations.push_back({"frame_2.png", 3, 3, 3, 2, true, 0.01, 0.5});
  WriteMapperCheckpoint(path, growing, fingerprint);
  writer.AddWithEdgeCases("growing", ReadBytes(path));
  WriteMapperCheckpoint(path, MapperCheckpoint(), fingerprint);
  writer.Add("nothing_mapped", ReadBytes(path));
  WriteMapperCheckpoint(path, finished, {{"fuzz", 2}});
  writer.Add("other_fingerprint", ReadBytes(path));
  writer.Add("empty", "");
}

}  // namespace
}  // namespace loopsfm::fuzz

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: write_seed_corpus CORPUS_DIR (tests/fuzz/corpus)\n");
    return 2;
  }
  const std::filesystem::path root = argv[1];
  loopsfm::fuzz::WriteModels(root);
  loopsfm::fuzz::WriteDatasetFiles(root);
  loopsfm::fuzz::WriteVocabularyTrees(root);
  loopsfm::fuzz::WriteDatabaseRows(root);
  loopsfm::fuzz::WriteMapperCheckpoints(root);
  return 0;
}
