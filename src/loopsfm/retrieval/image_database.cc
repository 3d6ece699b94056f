#include "loopsfm/retrieval/image_database.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

constexpr uint32_t kNoIndex = std::numeric_limits<uint32_t>::max();

// SimilarityMatrix() scores the words that are in many images with a dense product: a word in
// at least this fraction of the images (and at least kMinDensePostings), most frequent first,
// while the dense matrix stays under kMaxDenseBytes. A sparse list costs about n_w^2 / 2
// scattered additions, a dense column n^2 / 2 vectorised ones; the fractions are where the two
// cost the same in bench_retrieval.
constexpr double kDenseFractionL2 = 1.0 / 8;  // GEMM
constexpr double kDenseFractionL1 = 1.0 / 4;  // vectorised min-sum
constexpr size_t kMinDensePostings = 64;
constexpr size_t kMaxDenseBytes = size_t{512} << 20;
// Rows per task of the dense product (fixed, so results do not depend on the thread count).
constexpr int64_t kDenseRowBlock = 64;
// QueryAll ranks the columns of SimilarityMatrix() up to this many images.
constexpr int kMaxImagesForMatrixQueryAll = 8192;
// Images per task of Candidates() and ForEachSimilarityRow(): each task reuses one row of n
// scores across its images, and ForEachSimilarityRow() holds one block of rows.
constexpr int kQueryRowBlock = 64;

using RowMajorMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// similarity(i, j) = sum_k min(dense(i, k), dense(j, k)) for j <= i, i in [begin, end): rows i
// go kTile at a time against each row j (read once per tile), 16 words per vector register.
void MinSumLowerRows(const RowMajorMatrixXf& dense, int64_t begin, int64_t end,
                     Eigen::MatrixXf& similarity) {
  using Lanes = Eigen::Array<float, 16, 1>;
  constexpr int kTile = 8;
  const int64_t m = dense.cols();  // a multiple of 16
  for (int64_t i0 = begin; i0 < end; i0 += kTile) {
    const int tile = static_cast<int>(std::min<int64_t>(kTile, end - i0));
    const float* rows[kTile];
    for (int t = 0; t < kTile; ++t) rows[t] = dense.row(i0 + std::min(t, tile - 1)).data();
    for (int64_t j = 0; j < i0 + tile; ++j) {
      const float* other = dense.row(j).data();
      Lanes sums[kTile];
      for (Lanes& sum : sums) sum.setZero();
      for (int64_t k = 0; k < m; k += 16) {
        const Lanes b = Eigen::Map<const Lanes>(other + k);
        for (int t = 0; t < kTile; ++t) sums[t] += Eigen::Map<const Lanes>(rows[t] + k).min(b);
      }
      for (int t = 0; t < tile; ++t) {
        if (j <= i0 + t) similarity(i0 + t, j) = sums[t].sum();
      }
    }
  }
}

// similarity(i, j) for j <= i = sum_k f(dense(i, k), dense(j, k)): f = product (one GEMM per
// block of rows) or min. Blocks of rows are independent tasks.
void DenseLowerTriangle(const RowMajorMatrixXf& dense, TfIdfNorm norm,
                        Eigen::MatrixXf& similarity) {
  const int64_t n = dense.rows();
  const int64_t num_blocks = (n + kDenseRowBlock - 1) / kDenseRowBlock;
  tbb::parallel_for(int64_t{0}, num_blocks, [&](int64_t block) {
    const int64_t begin = block * kDenseRowBlock;
    const int64_t rows = std::min(kDenseRowBlock, n - begin);
    if (norm == TfIdfNorm::kL2) {
      similarity.block(begin, 0, rows, begin + rows).noalias() =
          dense.middleRows(begin, rows) * dense.topRows(begin + rows).transpose();
      return;
    }
    MinSumLowerRows(dense, begin, begin + rows, similarity);
  });
}

// Sorted distinct words with their counts.
void CountWords(std::vector<uint32_t> words, int num_words, std::vector<uint32_t>& distinct,
                std::vector<float>& counts) {
  std::sort(words.begin(), words.end());
  for (size_t i = 0; i < words.size();) {
    if (words[i] >= static_cast<uint32_t>(num_words)) {
      throw InvalidArgument(
          fmt::format("visual word {} is out of range: the database has {} words "
                      "(was the image quantised with another tree?)",
                      words[i], num_words));
    }
    size_t j = i + 1;
    while (j < words.size() && words[j] == words[i]) ++j;
    distinct.push_back(words[i]);
    counts.push_back(static_cast<float>(j - i));
    i = j;
  }
}

// Multiplies counts by the IDF weights, drops zeros and normalises, in place on [begin, end)
// of (words, values); returns the new end.
size_t WeightAndNormalise(std::vector<uint32_t>& words, std::vector<float>& values, size_t begin,
                          size_t end, const std::vector<float>& idf, TfIdfNorm norm) {
  size_t out = begin;
  double total = 0;
  for (size_t i = begin; i < end; ++i) {
    const float weight = values[i] * idf[words[i]];
    if (weight <= 0) continue;
    words[out] = words[i];
    values[out] = weight;
    total += norm == TfIdfNorm::kL1 ? double{weight} : double{weight} * weight;
    ++out;
  }
  if (total > 0) {
    const double inv = 1.0 / (norm == TfIdfNorm::kL1 ? total : std::sqrt(total));
    for (size_t i = begin; i < out; ++i) values[i] = static_cast<float>(values[i] * inv);
  }
  return out;
}

// The contribution of one shared word to a score; symmetric in its arguments, so that the
// score of (a, b) is bit-identical to that of (b, a).
template <TfIdfNorm kNorm>
inline float Term(float a, float b) {
  if constexpr (kNorm == TfIdfNorm::kL2) {
    return a * b;
  } else {
    return std::min(a, b);
  }
}

// Keeps the best `count` of `candidates` (indices into scores), sorted best first: score
// descending, then index ascending, so the order does not depend on how candidates was filled.
void KeepBest(const float* scores, size_t count, std::vector<uint32_t>& candidates) {
  const auto better = [&](uint32_t a, uint32_t b) {
    return scores[a] > scores[b] || (scores[a] == scores[b] && a < b);
  };
  count = std::min(count, candidates.size());
  std::partial_sort(candidates.begin(), candidates.begin() + count, candidates.end(), better);
  candidates.resize(count);
}

std::vector<ScoredIndex> ToScoredIndices(const float* scores,
                                         const std::vector<uint32_t>& indices) {
  std::vector<ScoredIndex> out(indices.size());
  for (size_t k = 0; k < indices.size(); ++k) {
    out[k] = {static_cast<int>(indices[k]), scores[indices[k]]};
  }
  return out;
}

}  // namespace

void ImageDatabaseOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(norm == TfIdfNorm::kL1 || norm == TfIdfNorm::kL2, "unknown TF-IDF norm {}",
                         static_cast<int>(norm));
}

ImageDatabase::ImageDatabase(int num_words, const ImageDatabaseOptions& options)
    : num_words_(num_words), options_(options) {
  options.Check();
  LOOPSFM_REQUIRE_OPTION(num_words >= 1, "an image database needs at least one word, got {}",
                         num_words);
}

void ImageDatabase::AddImage(image_t image_id, const std::vector<uint32_t>& words) {
  LOOPSFM_CHECK_MSG(!finalized_, "ImageDatabase::AddImage after Finalize");
  if (image_id == kInvalidImageId) throw InvalidArgument("cannot index kInvalidImageId");
  if (index_of_.count(image_id)) {
    throw InvalidArgument(fmt::format("image {} is already in the database", image_id));
  }
  std::vector<uint32_t> distinct;
  std::vector<float> counts;
  CountWords(words, num_words_, distinct, counts);
  index_of_.emplace(image_id, static_cast<uint32_t>(image_ids_.size()));
  image_ids_.push_back(image_id);
  image_words_.insert(image_words_.end(), distinct.begin(), distinct.end());
  image_values_.insert(image_values_.end(), counts.begin(), counts.end());
  image_begin_.push_back(image_words_.size());
}

void ImageDatabase::Finalize() {
  LOOPSFM_CHECK_MSG(!finalized_, "ImageDatabase::Finalize called twice");
  const size_t n = image_ids_.size();
  std::vector<uint32_t> document_frequency(num_words_, 0);
  for (const uint32_t word : image_words_) ++document_frequency[word];
  idf_.assign(num_words_, 0.0f);
  for (int w = 0; w < num_words_; ++w) {
    if (document_frequency[w] > 0) {
      idf_[w] = static_cast<float>(std::log(static_cast<double>(n) / document_frequency[w]));
    }
  }
  // Weight and normalise each image, compacting the arrays as zero weights drop out.
  size_t out = 0;
  for (size_t i = 0; i < n; ++i) {
    const size_t begin = image_begin_[i], end = image_begin_[i + 1];
    if (out != begin) {  // out < begin: a forward copy is safe
      std::copy(image_words_.begin() + begin, image_words_.begin() + end,
                image_words_.begin() + out);
      std::copy(image_values_.begin() + begin, image_values_.begin() + end,
                image_values_.begin() + out);
    }
    image_begin_[i] = out;
    out = WeightAndNormalise(image_words_, image_values_, out, out + (end - begin), idf_,
                             options_.norm);
  }
  image_begin_[n] = out;
  image_words_.resize(out);
  image_values_.resize(out);
  image_words_.shrink_to_fit();
  image_values_.shrink_to_fit();

  // Inverted file by counting sort; images go in in index order, so each list is sorted.
  LOOPSFM_CHECK_LT(out, size_t{kNoIndex});
  word_begin_.assign(num_words_ + 1, 0);
  for (const uint32_t word : image_words_) ++word_begin_[word + 1];
  for (int w = 0; w < num_words_; ++w) word_begin_[w + 1] += word_begin_[w];
  posting_images_.resize(out);
  posting_weights_.resize(out);
  image_posting_.resize(out);
  std::vector<size_t> next(word_begin_.begin(), word_begin_.end() - 1);
  for (size_t i = 0; i < n; ++i) {
    for (size_t k = image_begin_[i]; k < image_begin_[i + 1]; ++k) {
      const size_t slot = next[image_words_[k]]++;
      posting_images_[slot] = static_cast<uint32_t>(i);
      posting_weights_[slot] = image_values_[k];
      image_posting_[k] = static_cast<uint32_t>(slot);
    }
  }
  finalized_ = true;
}

float ImageDatabase::IdfWeight(uint32_t word) const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::IdfWeight before Finalize");
  LOOPSFM_CHECK_LT(word, idf_.size());
  return idf_[word];
}

uint32_t ImageDatabase::IndexOf(image_t image_id) const {
  const auto it = index_of_.find(image_id);
  if (it == index_of_.end()) {
    throw InvalidArgument(fmt::format("image {} is not in the database", image_id));
  }
  return it->second;
}

ImageDatabase::SparseVector ImageDatabase::ImageVectorAt(uint32_t index) const {
  const size_t begin = image_begin_[index];
  return {image_words_.data() + begin, image_values_.data() + begin,
          image_begin_[index + 1] - begin};
}

std::vector<std::pair<uint32_t, float>> ImageDatabase::ImageVector(image_t image_id) const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::ImageVector before Finalize");
  const SparseVector v = ImageVectorAt(IndexOf(image_id));
  std::vector<std::pair<uint32_t, float>> out(v.size);
  for (size_t i = 0; i < v.size; ++i) out[i] = {v.words[i], v.weights[i]};
  return out;
}

void ImageDatabase::Score(const SparseVector& query, float* scores) const {
  auto accumulate = [&]<TfIdfNorm kNorm>() {
    for (size_t i = 0; i < query.size; ++i) {
      const float q = query.weights[i];
      const size_t end = word_begin_[query.words[i] + 1];
      for (size_t k = word_begin_[query.words[i]]; k < end; ++k) {
        scores[posting_images_[k]] += Term<kNorm>(q, posting_weights_[k]);
      }
    }
  };
  if (options_.norm == TfIdfNorm::kL2) {
    accumulate.template operator()<TfIdfNorm::kL2>();
  } else {
    accumulate.template operator()<TfIdfNorm::kL1>();
  }
}

std::vector<ImageScore> ImageDatabase::Rank(const float* scores, uint32_t exclude,
                                            int max_results) const {
  std::vector<uint32_t> candidates;
  for (uint32_t i = 0; i < image_ids_.size(); ++i) {
    if (scores[i] > 0 && i != exclude) candidates.push_back(i);
  }
  KeepBest(scores, max_results > 0 ? static_cast<size_t>(max_results) : candidates.size(),
           candidates);
  std::vector<ImageScore> ranked(candidates.size());
  for (size_t i = 0; i < candidates.size(); ++i) {
    ranked[i] = {image_ids_[candidates[i]], scores[candidates[i]]};
  }
  return ranked;
}

std::vector<ImageScore> ImageDatabase::Query(image_t image_id, int max_results) const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::Query before Finalize");
  const uint32_t index = IndexOf(image_id);
  std::vector<float> scores(image_ids_.size(), 0.0f);
  Score(ImageVectorAt(index), scores.data());
  return Rank(scores.data(), index, max_results);
}

std::vector<ImageScore> ImageDatabase::Query(const std::vector<uint32_t>& words,
                                             int max_results) const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::Query before Finalize");
  std::vector<uint32_t> distinct;
  std::vector<float> values;
  CountWords(words, num_words_, distinct, values);
  const size_t size = WeightAndNormalise(distinct, values, 0, distinct.size(), idf_, options_.norm);
  std::vector<float> scores(image_ids_.size(), 0.0f);
  Score({distinct.data(), values.data(), size}, scores.data());
  return Rank(scores.data(), kNoIndex, max_results);
}

std::vector<std::vector<ImageScore>> ImageDatabase::QueryAll(int max_results) const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::QueryAll before Finalize");
  const size_t n = image_ids_.size();
  std::vector<std::vector<ImageScore>> results(n);
  if (n <= kMaxImagesForMatrixQueryAll) {
    const Eigen::MatrixXf similarity = SimilarityMatrix();
    tbb::parallel_for(size_t{0}, n, [&](size_t i) {
      results[i] = Rank(similarity.col(static_cast<int64_t>(i)).data(), static_cast<uint32_t>(i),
                        max_results);
    });
    return results;
  }
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    std::vector<float> scores(n, 0.0f);
    Score(ImageVectorAt(static_cast<uint32_t>(i)), scores.data());
    results[i] = Rank(scores.data(), static_cast<uint32_t>(i), max_results);
  });
  return results;
}

SimilarityCandidates ImageDatabase::Candidates(int num_best, int num_far, int min_index_gap) const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::Candidates before Finalize");
  LOOPSFM_CHECK_GE(num_best, 0);
  LOOPSFM_CHECK_GE(num_far, 0);
  LOOPSFM_CHECK_GE(min_index_gap, 0);
  const int64_t n = NumImages();
  SimilarityCandidates candidates;
  candidates.best.resize(n);
  candidates.far.resize(n);
  const int64_t num_blocks = (n + kQueryRowBlock - 1) / kQueryRowBlock;
  tbb::parallel_for(int64_t{0}, num_blocks, [&](int64_t block) {
    std::vector<float> scores(n, 0.0f);
    std::vector<uint32_t> best, far;
    const int64_t end = std::min(n, (block + 1) * kQueryRowBlock);
    for (int64_t i = block * kQueryRowBlock; i < end; ++i) {
      Score(ImageVectorAt(static_cast<uint32_t>(i)), scores.data());
      best.clear();
      far.clear();
      for (int64_t j = 0; j < n; ++j) {
        if (scores[j] <= 0 || j == i) continue;
        best.push_back(static_cast<uint32_t>(j));
        if (std::abs(i - j) > min_index_gap) far.push_back(static_cast<uint32_t>(j));
      }
      KeepBest(scores.data(), num_best, best);
      KeepBest(scores.data(), num_far, far);
      candidates.best[i] = ToScoredIndices(scores.data(), best);
      candidates.far[i] = ToScoredIndices(scores.data(), far);
      std::fill(scores.begin(), scores.end(), 0.0f);
    }
  });
  return candidates;
}

void ImageDatabase::ForEachSimilarityRow(
    const std::function<void(int row, const float* scores)>& visit) const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::ForEachSimilarityRow before Finalize");
  const int64_t n = NumImages();
  std::vector<float> rows(static_cast<size_t>(std::min<int64_t>(n, kQueryRowBlock) * n));
  for (int64_t begin = 0; begin < n; begin += kQueryRowBlock) {
    const int64_t end = std::min(n, begin + kQueryRowBlock);
    std::fill(rows.begin(), rows.begin() + (end - begin) * n, 0.0f);
    // The self-score comes out of Score too: the image is in the list of each of its words.
    tbb::parallel_for(begin, end, [&](int64_t i) {
      Score(ImageVectorAt(static_cast<uint32_t>(i)), rows.data() + (i - begin) * n);
    });
    for (int64_t i = begin; i < end; ++i) visit(static_cast<int>(i), rows.data() + (i - begin) * n);
  }
}

Eigen::MatrixXf ImageDatabase::SimilarityMatrix() const {
  LOOPSFM_CHECK_MSG(finalized_, "ImageDatabase::SimilarityMatrix before Finalize");
  const int64_t n = NumImages();
  Eigen::MatrixXf similarity = Eigen::MatrixXf::Zero(n, n);
  if (n == 0) return similarity;

  // Words in many images: a dense n x m matrix (m padded to whole cache lines, so that every
  // row starts aligned), scored by a dense product into the lower triangle.
  const double fraction = options_.norm == TfIdfNorm::kL2 ? kDenseFractionL2 : kDenseFractionL1;
  const double min_dense = std::max<double>(kMinDensePostings, fraction * n);
  std::vector<uint32_t> frequent;
  for (int w = 0; w < num_words_; ++w) {
    if (word_begin_[w + 1] - word_begin_[w] >= min_dense) frequent.push_back(w);
  }
  std::stable_sort(frequent.begin(), frequent.end(), [&](uint32_t a, uint32_t b) {
    return word_begin_[a + 1] - word_begin_[a] > word_begin_[b + 1] - word_begin_[b];
  });
  frequent.resize(std::min(frequent.size(), kMaxDenseBytes / (sizeof(float) * n)));
  std::vector<uint8_t> is_frequent(num_words_, 0);
  if (!frequent.empty()) {
    const int64_t m = (static_cast<int64_t>(frequent.size()) + 15) / 16 * 16;  // zero padding
    RowMajorMatrixXf dense = RowMajorMatrixXf::Zero(n, m);
    for (size_t c = 0; c < frequent.size(); ++c) {
      const uint32_t w = frequent[c];
      is_frequent[w] = 1;
      for (size_t k = word_begin_[w]; k < word_begin_[w + 1]; ++k) {
        dense(posting_images_[k], static_cast<int64_t>(c)) = posting_weights_[k];
      }
    }
    DenseLowerTriangle(dense, options_.norm, similarity);
  }

  // The other words through the inverted file: column j gets, for each of its words, the
  // images after j in the word's list (each pair once). Columns are independent tasks.
  auto sparse_column = [&]<TfIdfNorm kNorm>(int64_t j) {
    float* column = similarity.col(j).data();
    const size_t end_k = image_begin_[j + 1];
    for (size_t k = image_begin_[j]; k < end_k; ++k) {
      const uint32_t w = image_words_[k];
      if (is_frequent[w]) continue;
      if (k + 4 < end_k) {
        __builtin_prefetch(posting_images_.data() + image_posting_[k + 4]);
        __builtin_prefetch(posting_weights_.data() + image_posting_[k + 4]);
      }
      const float q = image_values_[k];
      const size_t end = word_begin_[w + 1];
      for (size_t p = image_posting_[k] + 1; p < end; ++p) {
        column[posting_images_[p]] += Term<kNorm>(q, posting_weights_[p]);
      }
    }
  };
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, n, 1), [&](const auto& range) {
    for (int64_t j = range.begin(); j < range.end(); ++j) {
      if (options_.norm == TfIdfNorm::kL2) {
        sparse_column.template operator()<TfIdfNorm::kL2>(j);
      } else {
        sparse_column.template operator()<TfIdfNorm::kL1>(j);
      }
    }
  });

  // Self-scores on the diagonal, then the lower triangle mirrored.
  for (int64_t j = 0; j < n; ++j) {
    const SparseVector v = ImageVectorAt(static_cast<uint32_t>(j));
    float self = 0;
    for (size_t i = 0; i < v.size; ++i) {
      self += options_.norm == TfIdfNorm::kL2 ? v.weights[i] * v.weights[i] : v.weights[i];
    }
    similarity(j, j) = self;
  }
  for (int64_t j = 0; j < n; ++j) {
    for (int64_t i = j + 1; i < n; ++i) similarity(j, i) = similarity(i, j);
  }
  return similarity;
}

ImageDatabase BuildImageDatabase(const VocabularyTree& tree, const std::vector<image_t>& image_ids,
                                 const std::vector<const FeatureDescriptors*>& descriptors,
                                 const ImageDatabaseOptions& options) {
  LOOPSFM_CHECK_EQ(image_ids.size(), descriptors.size());
  const std::vector<std::vector<uint32_t>> words = tree.QuantizeAll(descriptors);
  ImageDatabase database(tree.NumWords(), options);
  for (size_t i = 0; i < image_ids.size(); ++i) database.AddImage(image_ids[i], words[i]);
  database.Finalize();
  return database;
}

}  // namespace loopsfm
