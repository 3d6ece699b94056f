// The vocabtree pairing strategy: sequential neighbours first, then rounds of pairs proposed
// by the vocabulary tree's similarity candidates and grown around verified pairs. Nothing here
// is n x n: pairs are sparse sets, the similarity a few dozen partners per frame.

#include <filesystem>
#include <fstream>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "loopsfm/matching/pair_set.h"
#include "loopsfm/pipeline/match.h"
#include "loopsfm/pipeline/vocab_build.h"
#include "loopsfm/retrieval/image_database.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

// Partners kept per frame from the similarity (ImageDatabase::Candidates): its best frames
// overall, for bridging weak frames, and its best beyond the sequential window, for the loop
// proposals. The first round proposes about one pair per frame and later rounds fewer, so a
// few dozen per frame hold every pair the rounds reach for; memory stays linear in the frames.
constexpr int kBestCandidates = 32;
constexpr int kLoopCandidates = 32;
// The matrix pictures have at most this many cells a side (frames are binned beyond that).
constexpr int kMaxPictureCells = 1200;

// Trains a tree on a bounded sample: an equal share of random descriptors of every frame,
// read one frame at a time.
VocabularyTree TrainSceneTree(const Database& database, const std::vector<image_t>& ids,
                              const VocabTreeOptions& options, Random& random) {
  const size_t per_frame =
      std::max<size_t>(1, options.max_training_descriptors / std::max<size_t>(1, ids.size()));
  std::vector<FeatureDescriptors> samples;
  size_t total = 0;
  for (image_t id : ids) {
    FeatureDescriptors sample = SampleDescriptorRows(database.ReadDescriptors(id),
                                                     static_cast<int>(per_frame), random);
    total += sample.rows();
    samples.push_back(std::move(sample));
  }
  FeatureDescriptors training(total, kDescriptorDim);
  size_t row = 0;
  for (const auto& sample : samples) {
    training.middleRows(row, sample.rows()) = sample;
    row += sample.rows();
  }
  return VocabularyTree::Train(std::move(training), options, random);
}

// A picture of an n x n frame matrix from sparse entries: frames binned into at most
// kMaxPictureCells cells a side, each cell the largest value put in it.
class MatrixPicture {
 public:
  explicit MatrixPicture(int n)
      : n_(n), cells_(std::min(n, kMaxPictureCells)),
        values_(static_cast<size_t>(cells_) * cells_, 0.0f) {}
  void Put(int i, int j, float value) {
    float& cell = values_[static_cast<size_t>(Cell(i)) * cells_ + Cell(j)];
    cell = std::max(cell, value);
  }
  // Colour-mapped, normalised to the largest value.
  void Write(const std::filesystem::path& path) const {
    if (cells_ == 0) return;
    const float max = std::max(*std::max_element(values_.begin(), values_.end()), 1e-12f);
    cv::Mat grey(cells_, cells_, CV_8U);
    for (int i = 0; i < cells_; ++i) {
      for (int j = 0; j < cells_; ++j) {
        grey.at<uint8_t>(i, j) = static_cast<uint8_t>(
            std::clamp(255.0f * values_[static_cast<size_t>(i) * cells_ + j] / max, 0.0f, 255.0f));
      }
    }
    const int scale = std::max(1, 600 / cells_);
    cv::resize(grey, grey, cv::Size(), scale, scale, cv::INTER_NEAREST);
    cv::Mat colour;
    cv::applyColorMap(grey, colour, cv::COLORMAP_VIRIDIS);
    if (!cv::imwrite(path.string(), colour)) spdlog::warn("could not write {}", path.string());
  }

 private:
  int Cell(int i) const { return static_cast<int>(static_cast<int64_t>(i) * cells_ / n_); }
  int n_, cells_;
  std::vector<float> values_;
};

// The similarity matrix as text: a line of frame names, then one row of scores per frame,
// streamed row by row.
void WriteSimilarityText(const ImageDatabase& images, const std::vector<Frame>& frames,
                         const std::filesystem::path& path) {
  std::ofstream out(path);
  for (size_t i = 0; i < frames.size(); ++i) out << (i ? " " : "") << frames[i].name;
  out << "\n";
  const int n = images.NumImages();
  images.ForEachSimilarityRow([&](int, const float* row) {
    for (int j = 0; j < n; ++j) out << (j ? " " : "") << row[j];
    out << "\n";
  });
  if (!out) throw StorageError(fmt::format("cannot write the similarity matrix to '{}'", path.string()));
}

}  // namespace

void MatchVocabTreeGuided(Database& database, const std::vector<image_t>& ordered_ids,
                          const MatchOptions& options, PairMatcher& matcher, MatchReport* report) {
  const int n = static_cast<int>(ordered_ids.size());
  std::unordered_map<image_t, int> index_of;
  for (int i = 0; i < n; ++i) index_of[ordered_ids[i]] = i;
  IndexPairSet tried(n), verified(n), sequential(n);
  Timer timer;
  if (options.vocab_include_sequential) {
    auto verify = [&](const std::vector<ImagePair>& pairs) { return matcher.Match(pairs, report); };
    report->vocab.sequential =
        RunSequentialWaves(ordered_ids, options.sequential, options.sequential_waves, verify, &tried,
                           &verified, &sequential);
    const auto& seq = report->vocab.sequential;
    spdlog::info("vocabtree: sequential waves {} pairs ({} verified), of which quadratic steps {} ({} verified)",
                 seq.num_tried, seq.num_verified, seq.num_quadratic_tried, seq.num_quadratic_verified);
  }
  // Pairs stored by an earlier run are not marked tried up front: the rounds below propose
  // exactly what an uninterrupted run proposes, and the matcher hands back a stored pair's
  // result without matching it again. A resumed run thus ends with the same pairs as one
  // that was never interrupted (pairs of other strategies still reach the mapper, which
  // reads every verified pair).
  report->vocab.match_seconds += timer.ElapsedSeconds();

  timer.Restart();
  Random random(options.seed);
  const VocabularyTree tree = options.vocab_path.empty()
                                  ? TrainSceneTree(database, ordered_ids, options.vocab_tree, random)
                                  : VocabularyTree::Load(options.vocab_path);
  report->vocab.build_seconds = timer.ElapsedSeconds();

  timer.Restart();
  ImageDatabase images(tree.NumWords());
  // Batches of frames go down the tree together (each node's centres are read once per
  // batch); the batch bounds the descriptors held in memory.
  constexpr size_t kBatch = 16;
  for (size_t begin = 0; begin < ordered_ids.size(); begin += kBatch) {
    const size_t end = std::min(ordered_ids.size(), begin + kBatch);
    std::vector<FeatureDescriptors> batch;
    for (size_t i = begin; i < end; ++i) batch.push_back(database.ReadDescriptors(ordered_ids[i]));
    std::vector<const FeatureDescriptors*> pointers;
    for (const auto& d : batch) pointers.push_back(&d);
    const auto words = tree.QuantizeAll(pointers);
    for (size_t i = begin; i < end; ++i) images.AddImage(ordered_ids[i], words[i - begin]);
  }
  images.Finalize();
  GuidedPairingOptions guided = options.guided;
  // Score proposals leave the sequential window to the sequential part; pairs the waves
  // covered do not count as loop partners.
  if (options.vocab_include_sequential) guided.min_frame_gap = std::max(guided.min_frame_gap, options.sequential.overlap);
  const SimilarityCandidates candidates =
      images.Candidates(kBestCandidates, kLoopCandidates, guided.min_frame_gap);
  report->vocab.score_seconds = timer.ElapsedSeconds();
  if (!options.similarity_path.empty()) {
    WriteSimilarityText(images, FramesInCaptureOrder(database), options.similarity_path);
  }
  spdlog::info("vocabtree: {} words, {:.1f} s tree, {:.1f} s scoring", tree.NumWords(),
               report->vocab.build_seconds, report->vocab.score_seconds);

  double match_seconds = 0.0;
  Timer rounds_timer;
  auto verify = [&](const std::vector<ImagePair>& pairs) {
    Timer match_timer;
    std::vector<bool> ok = matcher.Match(pairs, report);
    match_seconds += match_timer.ElapsedSeconds();
    return ok;
  };
  report->vocab.guided = RunGuidedPairing(candidates.far, ordered_ids, guided, verify, &tried,
                                          &verified, &sequential);
  report->vocab.match_seconds += match_seconds;
  report->vocab.propose_seconds = rounds_timer.ElapsedSeconds() - match_seconds;
  for (size_t r = 0; r < report->vocab.guided.rounds.size(); ++r) {
    const auto& round = report->vocab.guided.rounds[r];
    spdlog::info("vocabtree round {}: {} by score ({} verified), {} by region growing ({} verified)",
                 r + 1, round.num_from_scores, round.num_verified_from_scores,
                 round.num_from_growing, round.num_verified - round.num_verified_from_scores);
  }
  if (options.vocab_bridging) {
    Timer bridging_timer;
    const double match_before = match_seconds;
    report->vocab.bridging = BridgeViewGraph(candidates.best, ordered_ids, options.bridging, verify, &tried, &verified);
    report->vocab.match_seconds += match_seconds - match_before;
    report->vocab.propose_seconds += bridging_timer.ElapsedSeconds() - (match_seconds - match_before);
    const auto& b = report->vocab.bridging;
    spdlog::info("vocabtree: view graph {} component(s), largest {} of {} frames; bridging tried {} "
                 "pairs ({} verified) in {} rounds: {} component(s), largest {}",
                 b.num_components_before, b.largest_component_before, n, b.num_tried, b.num_verified,
                 b.num_rounds, b.num_components_after, b.largest_component_after);
  }

  if (options.write_matrix_images) {
    const std::filesystem::path db_path(database.Path());
    // The similarity as far as pairing kept it: each frame's best and best distant partners.
    MatrixPicture similarity(n);
    for (int i = 0; i < n; ++i) {
      for (const auto* list : {&candidates.best[i], &candidates.far[i]}) {
        for (const ScoredIndex& c : *list) {
          similarity.Put(i, c.index, c.score);
          similarity.Put(c.index, i, c.score);
        }
      }
    }
    similarity.Write(db_path.parent_path() / (db_path.stem().string() + "_similarity.png"));
    MatrixPicture inliers(n);
    for (const VerifiedPair& pair : database.ReadVerifiedPairs()) {
      if (!index_of.count(pair.pair.image_id1) || !index_of.count(pair.pair.image_id2)) continue;
      const int i = index_of.at(pair.pair.image_id1), j = index_of.at(pair.pair.image_id2);
      inliers.Put(i, j, static_cast<float>(pair.num_inliers));
      inliers.Put(j, i, static_cast<float>(pair.num_inliers));
    }
    inliers.Write(db_path.parent_path() / (db_path.stem().string() + "_matches.png"));
  }
}

}  // namespace loopsfm
