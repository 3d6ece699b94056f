// Vocabulary-tree shapes on real image sequences: training time, quantisation time and
// retrieval quality, the measurements behind VocabTreeOptions' defaults.
//
//   retrieval_study [--configs=10x4,32x3,...] [--samples=250000] [--iterations=10]
//                   [--seed=N] FOLDER...
//
// Each FOLDER holds frames named in capture order (e.g. ../shared/data/kitti07_160/images), or
// is a video file (../shared/data/block/block.mp4, frames named frame_%06d).
// SIFT features are extracted once with loopsfm's defaults (RootSIFT, up to 8192 per frame) and
// cached in $TMPDIR as loopsfm_study_<hash>.bin. For each folder and tree shape k x L the
// tree is trained on a sample of the folder's own descriptors, every frame is indexed, and
// quality is precision@5: over frames, the fraction of the 5 best-scoring other frames that are
// temporal neighbours (|i - j| <= 3), for L1 and L2 normalised TF-IDF vectors. With two or more
// folders the tree of the first is also used on the others ("generic tree" rows).
// Where a groundtruth.txt lies beside the frames, loop recall@1 is reported too: over frames
// that revisit a place (another frame more than 30 frames away has its centre within 5 median
// frame steps and its optical axis within 30 degrees), the fraction whose best-scoring frame
// more than 30 frames away is such a revisit.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <tbb/parallel_for.h>

#include "loopsfm/feature/sift.h"
#include "loopsfm/retrieval/image_database.h"
#include "loopsfm/retrieval/vocabulary_tree.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;

struct Sequence {
  std::string name;
  std::vector<FeatureDescriptors> descriptors;  // per frame, capture order
  std::vector<std::vector<int>> revisits;       // per frame, frames > 30 away seeing the same
  std::vector<const FeatureDescriptors*> Pointers() const {
    std::vector<const FeatureDescriptors*> out;
    for (const auto& d : descriptors) out.push_back(&d);
    return out;
  }
  int64_t NumDescriptors() const {
    int64_t n = 0;
    for (const auto& d : descriptors) n += d.rows();
    return n;
  }
};

std::vector<fs::path> ListImages(const fs::path& folder) {
  std::vector<fs::path> images;
  for (const auto& entry : fs::directory_iterator(folder)) {
    std::string ext = entry.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
    if (ext == ".png" || ext == ".jpg" || ext == ".jpeg") images.push_back(entry.path());
  }
  std::sort(images.begin(), images.end());
  return images;
}

// Ground-truth revisits from groundtruth.txt beside the frames (lines: name tx ty tz qx qy qz
// qw, world_from_cam), in name order; empty when there is none.
std::vector<std::vector<int>> Revisits(const fs::path& folder) {
  std::ifstream in(folder.parent_path() / "groundtruth.txt");
  std::map<std::string, std::pair<Eigen::Vector3d, Eigen::Vector3d>> poses;  // centre, axis
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::string name;
    double t[3], q[4];
    if (!(fields >> name >> t[0] >> t[1] >> t[2] >> q[0] >> q[1] >> q[2] >> q[3])) continue;
    const Eigen::Quaterniond rotation(q[3], q[0], q[1], q[2]);
    poses[name] = {Eigen::Vector3d(t[0], t[1], t[2]),
                   rotation.normalized() * Eigen::Vector3d::UnitZ()};
  }
  if (poses.empty()) return {};
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> ordered;
  for (const auto& [name, pose] : poses) ordered.push_back(pose);
  std::vector<double> steps;
  for (size_t i = 1; i < ordered.size(); ++i) {
    steps.push_back((ordered[i].first - ordered[i - 1].first).norm());
  }
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  const double radius = 5 * steps[steps.size() / 2];
  const double min_cos = std::cos(30.0 * M_PI / 180.0);
  std::vector<std::vector<int>> revisits(ordered.size());
  for (size_t i = 0; i < ordered.size(); ++i) {
    for (size_t j = 0; j < ordered.size(); ++j) {
      if (std::abs(static_cast<int>(i) - static_cast<int>(j)) > 30 &&
          (ordered[i].first - ordered[j].first).norm() < radius &&
          ordered[i].second.dot(ordered[j].second) > min_cos) {
        revisits[i].push_back(static_cast<int>(j));
      }
    }
  }
  return revisits;
}

Sequence LoadSequence(const fs::path& folder) {
  Sequence sequence;
  sequence.name = folder.parent_path().filename().string() + "/" + folder.filename().string();
  sequence.revisits = Revisits(folder);
  const fs::path cache = fs::temp_directory_path() /
                         fmt::format("loopsfm_study_{:016x}.bin",
                                     std::hash<std::string>()(fs::absolute(folder).string()));
  if (std::ifstream in(cache, std::ios::binary); in) {
    int32_t count = 0;
    in.read(reinterpret_cast<char*>(&count), sizeof(count));
    sequence.descriptors.resize(count);
    for (auto& d : sequence.descriptors) {
      int32_t rows = 0;
      in.read(reinterpret_cast<char*>(&rows), sizeof(rows));
      d.resize(rows, kDescriptorDim);
      in.read(reinterpret_cast<char*>(d.data()), d.size());
    }
    if (in) return sequence;
  }
  std::vector<cv::Mat> frames;
  if (fs::is_directory(folder)) {
    for (const fs::path& image : ListImages(folder)) {
      frames.push_back(cv::imread(image.string(), cv::IMREAD_GRAYSCALE));
      if (frames.back().empty()) throw std::runtime_error("cannot read " + image.string());
    }
  } else {
    cv::VideoCapture video(folder.string());
    for (cv::Mat frame; video.read(frame);) {
      cv::Mat grey;
      cv::cvtColor(frame, grey, cv::COLOR_BGR2GRAY);
      frames.push_back(grey);
    }
  }
  if (frames.empty()) throw std::runtime_error("no frames in " + folder.string());
  sequence.descriptors.resize(frames.size());
  Timer timer;
  tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
    sequence.descriptors[i] = ExtractSift(frames[i], SiftOptions()).descriptors;
  });
  std::fprintf(stderr, "extracted SIFT from %zu frames of %s in %.1f s\n", frames.size(),
               sequence.name.c_str(), timer.ElapsedSeconds());
  std::ofstream out(cache, std::ios::binary);
  const int32_t count = static_cast<int32_t>(sequence.descriptors.size());
  out.write(reinterpret_cast<const char*>(&count), sizeof(count));
  for (const auto& d : sequence.descriptors) {
    const int32_t rows = static_cast<int32_t>(d.rows());
    out.write(reinterpret_cast<const char*>(&rows), sizeof(rows));
    out.write(reinterpret_cast<const char*>(d.data()), d.size());
  }
  return sequence;
}

// Fraction of the top-5 results of each frame that are within 3 frames of it.
double PrecisionAt5(const ImageDatabase& database) {
  const auto results = database.QueryAll(5);
  double sum = 0;
  for (size_t i = 0; i < results.size(); ++i) {
    int hits = 0;
    for (const ImageScore& s : results[i]) {
      hits += std::abs(static_cast<int>(s.image_id) - static_cast<int>(i)) <= 3;
    }
    sum += hits / 5.0;
  }
  return sum / static_cast<double>(results.size());
}

// Loop recall@1 (see the file comment); -1 without ground truth or revisits.
double LoopRecallAt1(const ImageDatabase& database, const std::vector<std::vector<int>>& revisits) {
  if (revisits.size() != static_cast<size_t>(database.NumImages())) return -1;
  int loops = 0, hits = 0;
  const auto results = database.QueryAll(0);
  for (size_t i = 0; i < revisits.size(); ++i) {
    if (revisits[i].empty()) continue;
    ++loops;
    for (const ImageScore& s : results[i]) {
      const int j = static_cast<int>(s.image_id);
      if (std::abs(j - static_cast<int>(i)) <= 30) continue;
      hits += std::find(revisits[i].begin(), revisits[i].end(), j) != revisits[i].end();
      break;
    }
  }
  return loops > 0 ? static_cast<double>(hits) / loops : -1;
}

struct Row {
  double quantize_ms_per_frame = 0, similarity_ms = 0;
  double precision[2] = {0, 0}, loop_recall[2] = {-1, -1};  // L1, L2
};

Row Evaluate(const VocabularyTree& tree, const Sequence& sequence) {
  Row row;
  std::vector<std::vector<uint32_t>> words(sequence.descriptors.size());
  Timer timer;
  for (size_t i = 0; i < words.size(); ++i) words[i] = tree.QuantizeAll(sequence.descriptors[i]);
  row.quantize_ms_per_frame = timer.ElapsedMillis() / static_cast<double>(words.size());
  if (std::getenv("STUDY_STATS")) {
    std::vector<int> postings(tree.NumWords(), 0);
    double distinct = 0;
    for (auto w : words) {
      std::sort(w.begin(), w.end());
      w.erase(std::unique(w.begin(), w.end()), w.end());
      distinct += w.size();
      for (uint32_t x : w) ++postings[x];
    }
    double pair_ops = 0;
    int over_eighth = 0, max_postings = 0;
    for (int p : postings) {
      pair_ops += 0.5 * p * p;
      over_eighth += p * 8 > static_cast<int>(words.size());
      max_postings = std::max(max_postings, p);
    }
    std::printf(
        "  stats: %.0f distinct words per frame, %.3g pair-ops, %d words in > 1/8 of the "
        "frames, max %d frames\n",
        distinct / words.size(), pair_ops, over_eighth, max_postings);
  }
  for (const TfIdfNorm norm : {TfIdfNorm::kL1, TfIdfNorm::kL2}) {
    ImageDatabaseOptions options;
    options.norm = norm;
    ImageDatabase database(tree.NumWords(), options);
    for (size_t i = 0; i < words.size(); ++i) database.AddImage(static_cast<image_t>(i), words[i]);
    database.Finalize();
    timer.Restart();
    const Eigen::MatrixXf similarity = database.SimilarityMatrix();
    if (norm == TfIdfNorm::kL1) row.similarity_ms = timer.ElapsedMillis();
    const int n = norm == TfIdfNorm::kL1 ? 0 : 1;
    row.precision[n] = PrecisionAt5(database);
    row.loop_recall[n] = LoopRecallAt1(database, sequence.revisits);
  }
  return row;
}

std::vector<std::string> Split(const std::string& s, char separator) {
  std::vector<std::string> parts;
  size_t begin = 0;
  for (size_t end; (end = s.find(separator, begin)) != std::string::npos; begin = end + 1) {
    parts.push_back(s.substr(begin, end - begin));
  }
  parts.push_back(s.substr(begin));
  return parts;
}

int Main(int argc, char** argv) {
  std::vector<std::pair<int, int>> configs = {{10, 4}, {10, 5},  {32, 3},
                                              {64, 2}, {100, 2}, {256, 2}};
  std::vector<int> samples = {250000};
  std::vector<int> iterations = {10};
  uint64_t seed = kDefaultRandomSeed;
  std::vector<fs::path> folders;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](const char* flag) {
      return arg.rfind(flag, 0) == 0 ? arg.substr(std::string(flag).size()) : std::string();
    };
    if (!value("--configs=").empty()) {
      configs.clear();
      for (const auto& c : Split(value("--configs="), ',')) {
        const auto kl = Split(c, 'x');
        configs.emplace_back(std::stoi(kl.at(0)), std::stoi(kl.at(1)));
      }
    } else if (!value("--samples=").empty()) {
      samples.clear();
      for (const auto& s : Split(value("--samples="), ',')) samples.push_back(std::stoi(s));
    } else if (!value("--iterations=").empty()) {
      iterations.clear();
      for (const auto& s : Split(value("--iterations="), ',')) iterations.push_back(std::stoi(s));
    } else if (!value("--seed=").empty()) {
      seed = std::stoull(value("--seed="));
    } else {
      folders.emplace_back(arg);
    }
  }
  if (folders.empty()) {
    std::fprintf(stderr,
                 "usage: retrieval_study [--configs=10x4,...] [--samples=N,...] "
                 "[--iterations=N,...] [--seed=N] FOLDER...\n");
    return 2;
  }
  std::vector<Sequence> sequences;
  for (const auto& folder : folders) {
    sequences.push_back(LoadSequence(folder));
    int loop_frames = 0;
    for (const auto& r : sequences.back().revisits) loop_frames += !r.empty();
    std::printf("%s: %zu frames, %lld descriptors, %d frames revisit a place\n",
                sequences.back().name.c_str(), sequences.back().descriptors.size(),
                static_cast<long long>(sequences.back().NumDescriptors()), loop_frames);
  }
  std::printf("\n%-22s %-22s %5s %3s %8s %5s %7s %8s %8s %7s %7s %7s %7s %7s\n", "trained on",
              "evaluated on", "k", "L", "sample", "iters", "words", "train_s", "quant_ms", "sim_ms",
              "P5_L1", "P5_L2", "R1_L1", "R1_L2");
  for (const Sequence& train_on : sequences) {
    for (const auto& [k, depth] : configs) {
      for (const int sample : samples) {
        for (const int iters : iterations) {
          VocabTreeOptions options;
          options.branching = k;
          options.depth = depth;
          options.max_training_descriptors = sample;
          options.kmeans_iterations = iters;
          Random random(seed);
          Timer timer;
          const VocabularyTree tree = VocabularyTree::Train(train_on.Pointers(), options, random);
          const double train_s = timer.ElapsedSeconds();
          for (const Sequence& evaluate_on : sequences) {
            if (&train_on != &sequences[0] && &evaluate_on != &train_on) continue;
            const Row row = Evaluate(tree, evaluate_on);
            std::printf(
                "%-22s %-22s %5d %3d %8d %5d %7d %8.2f %8.2f %7.1f %7.3f %7.3f %7.3f %7.3f\n",
                train_on.name.c_str(), evaluate_on.name.c_str(), k, depth, sample, iters,
                tree.NumWords(), train_s, row.quantize_ms_per_frame, row.similarity_ms,
                row.precision[0], row.precision[1], row.loop_recall[0], row.loop_recall[1]);
            std::fflush(stdout);
          }
        }
      }
    }
  }
  return 0;
}

}  // namespace
}  // namespace loopsfm

int main(int argc, char** argv) { return loopsfm::Main(argc, argv); }
