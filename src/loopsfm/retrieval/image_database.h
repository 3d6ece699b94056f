#pragma once
// Image retrieval with visual words (Nister & Stewenius 2006): every image becomes a sparse
// TF-IDF vector over the words of a vocabulary tree, normalised to unit length, and images are
// scored against each other through an inverted file (word -> images containing it), so a
// query touches only the images that share a word with it.
//
// Weighting: the entry of word i in image d is  tf * idf = n_id * log(N / N_i),  n_id the number
// of descriptors of d quantised to i, N the number of indexed images, N_i those containing i.
// Words present in every image get weight 0 and drop out (they tell images apart no better than
// chance). Scores lie in [0, 1], 1 for identical vectors:
//   kL2: vectors L2-normalised, score = dot product (cosine similarity);
//   kL1: vectors L1-normalised, score = sum_i min(q_i, d_i) = 1 - |q - d|_1 / 2, the L1
//        distance Nister & Stewenius score with, computed through the inverted file.
//
// Typical use:
//   ImageDatabase database(tree.NumWords());
//   for (...) database.AddImage(image_id, tree.QuantizeAll(descriptors));
//   database.Finalize();
//   Eigen::MatrixXf similarity = database.SimilarityMatrix();
// or BuildImageDatabase() below, which quantises all images in one grouped descent. For many
// images, Candidates() and ForEachSimilarityRow() give what pair selection and pictures need in
// memory linear in the number of images.

#include <cstdint>
#include <functional>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/retrieval/vocabulary_tree.h"
#include "loopsfm/scene/features.h"
#include "loopsfm/util/types.h"

namespace loopsfm {

enum class TfIdfNorm { kL1, kL2 };

struct ImageDatabaseOptions {
  // Normalisation of the TF-IDF vectors, which also picks the score (see the file comment).
  // Measured on real sequences, L1 and L2 retrieve equally well with 65k-250k-word trees (L1
  // is ahead by up to 2 points with 10k words); L2's similarity matrix is a little faster.
  TfIdfNorm norm = TfIdfNorm::kL2;
  // Throws loopsfm::InvalidArgument with a readable message.
  void Check() const;
};

struct ImageScore {
  image_t image_id = kInvalidImageId;
  float score = 0;
  friend bool operator==(const ImageScore&, const ImageScore&) = default;
};

// One image's partner: an index into ImageIds() and its score.
struct ScoredIndex {
  int index = -1;
  float score = 0;
  friend bool operator==(const ScoredIndex&, const ScoredIndex&) = default;
};

// Each image's best-scoring partners, best first (ties: lower index first), only partners with
// a positive score. Indexed like ImageIds().
struct SimilarityCandidates {
  // Per image: its best partners among all other images.
  std::vector<std::vector<ScoredIndex>> best;
  // Per image: its best partners among the images more than min_index_gap indices away
  // (|i - j| > min_index_gap). Indices are capture order, so these are loop candidates, not
  // temporal neighbours, which would otherwise crowd them out of `best`.
  std::vector<std::vector<ScoredIndex>> far;
};

class ImageDatabase {
 public:
  // A database over word ids 0 .. num_words - 1 (VocabularyTree::NumWords()).
  explicit ImageDatabase(int num_words, const ImageDatabaseOptions& options = {});

  // Adds an image by the words of its descriptors (in any order, repeats counted). Throws
  // InvalidArgument for a repeated or invalid image id or a word >= num_words.
  // Must come before Finalize().
  void AddImage(image_t image_id, const std::vector<uint32_t>& words);
  // Computes the IDF weights over the added images, the normalised vectors and the inverted
  // file. Queries need it; images cannot be added afterwards.
  void Finalize();
  bool IsFinalized() const { return finalized_; }

  int NumImages() const { return static_cast<int>(image_ids_.size()); }
  int NumWords() const { return num_words_; }
  // Image ids in the order they were added: the row / column order of SimilarityMatrix().
  const std::vector<image_t>& ImageIds() const { return image_ids_; }
  // log(N / N_i), or 0 for a word in no image or in every image. After Finalize().
  float IdfWeight(uint32_t word) const;
  // An image's normalised TF-IDF vector as (word, weight), sorted by word, zeros left out.
  std::vector<std::pair<uint32_t, float>> ImageVector(image_t image_id) const;

  // The images most similar to an indexed image, best first (ties: earlier added first),
  // the image itself left out; at most max_results (all when max_results <= 0), and only
  // images with a positive score. Throws InvalidArgument for an unknown id.
  std::vector<ImageScore> Query(image_t image_id, int max_results) const;
  // The same for an image outside the database, given by its words; words in no indexed image
  // carry no weight.
  std::vector<ImageScore> Query(const std::vector<uint32_t>& words, int max_results) const;
  // Query(id, max_results) for every image, in the order of ImageIds(), in parallel. Up to
  // 8192 images it ranks the columns of SimilarityMatrix(), whose scores may differ from
  // Query's in the last bits (and so order near-ties differently).
  std::vector<std::vector<ImageScore>> QueryAll(int max_results) const;
  // n x n symmetric scores in the order of ImageIds(); the diagonal holds each image's score
  // with itself (1 up to rounding; 0 for an image without weighted words). Words in many
  // images go through a dense product (a GEMM for kL2), the others through the inverted file,
  // each pair once. Entries equal Query's scores up to float rounding (relative 1e-6); the
  // result does not depend on the thread count. Memory is 4 n^2 bytes, plus up to 512 MiB
  // for the dense part: for many thousands of images use Candidates() to select pairs and
  // ForEachSimilarityRow() to draw or write the scores.
  Eigen::MatrixXf SimilarityMatrix() const;
  // Every image's num_best best partners and its num_far best partners more than
  // min_index_gap indices away (see SimilarityCandidates), each image queried through the
  // inverted file in parallel. Scores are Query's: each pair's shared words are summed in word
  // order from either side, so (i, j) and (j, i) score the same, and SimilarityMatrix() may
  // differ from them in the last bits. Memory is linear in the number of images (one row of
  // scores per thread, plus the lists); the result does not depend on the thread count.
  SimilarityCandidates Candidates(int num_best, int num_far, int min_index_gap) const;
  // Calls visit(row, scores) for row = 0 .. n - 1 in order, from the calling thread, with
  // scores[0 .. n) the row's scores as in Candidates() and the image's score with itself at
  // scores[row] (the diagonal of SimilarityMatrix()). scores is valid during the call only.
  // Blocks of rows are computed in parallel; at most one block is held.
  void ForEachSimilarityRow(const std::function<void(int row, const float* scores)>& visit) const;

 private:
  struct SparseVector {
    const uint32_t* words;
    const float* weights;
    size_t size;
  };
  SparseVector ImageVectorAt(uint32_t index) const;
  uint32_t IndexOf(image_t image_id) const;
  // Adds the scores of every indexed image against `query` to scores[0 .. n).
  void Score(const SparseVector& query, float* scores) const;
  // The best max_results of scores[0 .. n) as in Query, leaving out index `exclude`.
  std::vector<ImageScore> Rank(const float* scores, uint32_t exclude, int max_results) const;

  int num_words_;
  ImageDatabaseOptions options_;
  bool finalized_ = false;
  std::vector<image_t> image_ids_;
  std::unordered_map<image_t, uint32_t> index_of_;
  // Per image, (word, value) sorted by word in image_begin_[i] .. image_begin_[i + 1]: term
  // counts before Finalize(), normalised TF-IDF weights after (zero weights dropped).
  std::vector<size_t> image_begin_ = {0};
  std::vector<uint32_t> image_words_;
  std::vector<float> image_values_;
  // After Finalize(): IDF per word, and the inverted file: per word, (image index, weight)
  // sorted by image index in word_begin_[w] .. word_begin_[w + 1]; image_posting_[k] is where
  // entry k of image_words_ sits in its word's list.
  std::vector<float> idf_;
  std::vector<size_t> word_begin_;
  std::vector<uint32_t> posting_images_;
  std::vector<float> posting_weights_;
  std::vector<uint32_t> image_posting_;
};

// Quantises every image's descriptors with the tree (images in parallel) and returns the
// finalised database. ids and descriptors run in parallel (same length).
ImageDatabase BuildImageDatabase(const VocabularyTree& tree, const std::vector<image_t>& image_ids,
                                 const std::vector<const FeatureDescriptors*>& descriptors,
                                 const ImageDatabaseOptions& options = {});

}  // namespace loopsfm
