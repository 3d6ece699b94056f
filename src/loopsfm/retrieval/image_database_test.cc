#include "loopsfm/retrieval/image_database.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <set>

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include "loopsfm/retrieval/retrieval_test_data.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using retrieval_test::DrawFromCluster;
using retrieval_test::RandomCentres;

ImageDatabaseOptions WithNorm(TfIdfNorm norm) {
  ImageDatabaseOptions options;
  options.norm = norm;
  return options;
}

std::set<image_t> TopIds(const std::vector<ImageScore>& ranked, size_t count) {
  std::set<image_t> ids;
  for (size_t i = 0; i < std::min(count, ranked.size()); ++i) ids.insert(ranked[i].image_id);
  return ids;
}

class ImageDatabaseNormTest : public ::testing::TestWithParam<TfIdfNorm> {};

TEST_P(ImageDatabaseNormTest, WordsInEveryImageCarryNoWeight) {
  ImageDatabase database(10, WithNorm(GetParam()));
  database.AddImage(7, {0, 0, 1});
  database.AddImage(3, {0, 2});
  database.AddImage(5, {3, 0, 3, 1});
  database.Finalize();
  EXPECT_EQ(database.IdfWeight(0), 0.0f);
  EXPECT_FLOAT_EQ(database.IdfWeight(1), std::log(1.5f));
  EXPECT_FLOAT_EQ(database.IdfWeight(2), std::log(3.0f));
  EXPECT_EQ(database.IdfWeight(9), 0.0f);  // in no image
  const auto vector7 = database.ImageVector(7);
  ASSERT_EQ(vector7.size(), 1u);
  EXPECT_EQ(vector7[0].first, 1u);
  EXPECT_FLOAT_EQ(vector7[0].second, 1.0f);
  // Images 7 and 3 share only word 0: no score.
  const auto ranked = database.Query(7, 10);
  ASSERT_EQ(ranked.size(), 1u);
  EXPECT_EQ(ranked[0].image_id, 5u);
  const Eigen::MatrixXf similarity = database.SimilarityMatrix();
  EXPECT_EQ(similarity(0, 1), 0.0f);
  EXPECT_EQ(similarity(1, 0), 0.0f);
  EXPECT_GT(similarity(0, 2), 0.0f);
  // Image 5: word 3 twice (idf log 3), word 1 once (idf log 1.5).
  const double w3 = 2 * std::log(3.0), w1 = std::log(1.5);
  const double expected = GetParam() == TfIdfNorm::kL2
                              ? w1 / std::hypot(w1, w3)  // cosine with the unit vector on word 1
                              : std::min(1.0, w1 / (w1 + w3));
  EXPECT_NEAR(similarity(0, 2), expected, 1e-6);
}

TEST_P(ImageDatabaseNormTest, FrequentWordsCountLessThanRareOnes) {
  // Word 0 is in 9 of 10 images (idf 0.105), word 1 in 2 (idf 1.61). Image 0 shares word 0
  // three times with images 1..8, and word 1 once with image 9: image 9 must rank first.
  ImageDatabase database(100, WithNorm(GetParam()));
  database.AddImage(0, {0, 0, 0, 1, 90});
  for (image_t i = 1; i <= 8; ++i) database.AddImage(i, {0, 0, 0, 10 + i, 20 + i});
  database.AddImage(9, {1, 50, 51});
  database.Finalize();
  const auto ranked = database.Query(0, 3);
  ASSERT_EQ(ranked.size(), 3u);
  EXPECT_EQ(ranked[0].image_id, 9u);
  EXPECT_GT(ranked[0].score, 3 * ranked[1].score);
  EXPECT_EQ(ranked[1].image_id, 1u);  // images 1..8 tie: the first added wins
  EXPECT_EQ(ranked[1].score, ranked[2].score);
}

// Synthetic images along a path, like frames of a video. Each cluster stands for a scene
// point, seen once by every image that sees it (as a descriptor with a little noise): image i
// sees points 20i .. 20i + 79, so it shares 60 points with i +- 1, 40 with i +- 2 and 20 with
// i +- 3. Every image also sees the same 20 "background" points and 20 points of its own.
struct PathImages {
  std::vector<image_t> ids;
  std::vector<FeatureDescriptors> descriptors;
};

PathImages MakePathImages(int num_images, Random& random) {
  const int num_path = 20 * num_images + 60, num_background = 20, num_own = 20;
  const FeatureDescriptors centres =
      RandomCentres(num_path + num_background + num_own * num_images, random);
  PathImages images;
  for (int i = 0; i < num_images; ++i) {
    FeatureDescriptors d(0, kDescriptorDim);
    std::vector<int> seen;
    for (int c = 20 * i; c < 20 * i + 80; ++c) seen.push_back(c);
    for (int c = 0; c < num_background; ++c) seen.push_back(num_path + c);
    for (int c = 0; c < num_own; ++c) seen.push_back(num_path + num_background + num_own * i + c);
    for (const int c : seen) DrawFromCluster(centres, c, 1, 4.0, random, d);
    images.ids.push_back(100 + 2 * i);  // ids need not be contiguous
    images.descriptors.push_back(std::move(d));
  }
  return images;
}

TEST_P(ImageDatabaseNormTest, RetrievesNeighboursOnAPath) {
  Random random(21);
  const PathImages images = MakePathImages(40, random);
  std::vector<const FeatureDescriptors*> sets;
  for (const auto& d : images.descriptors) sets.push_back(&d);
  VocabTreeOptions tree_options;
  tree_options.branching = 16;
  tree_options.depth = 3;
  const VocabularyTree tree = VocabularyTree::Train(sets, tree_options, random);
  const ImageDatabase database = BuildImageDatabase(tree, images.ids, sets, WithNorm(GetParam()));
  ASSERT_EQ(database.NumImages(), 40);
  EXPECT_EQ(database.ImageIds(), images.ids);

  for (int i = 0; i < 40; ++i) {
    const auto ranked = database.Query(images.ids[i], 6);
    std::set<image_t> expected2, expected4;
    for (int j : {i - 1, i + 1}) {
      if (j >= 0 && j < 40) expected2.insert(images.ids[j]);
    }
    expected4 = expected2;
    for (int j : {i - 2, i + 2}) {
      if (j >= 0 && j < 40) expected4.insert(images.ids[j]);
    }
    // The nearest neighbours come first. L2 scores weigh words that several points fell into
    // more (squared counts) and can swap i +- 1 and i +- 2, so only L1 is held to the order.
    EXPECT_TRUE(expected2.count(ranked.at(0).image_id)) << "image " << i;
    if (GetParam() == TfIdfNorm::kL1) {
      EXPECT_EQ(TopIds(ranked, expected2.size()), expected2) << "image " << i;
    }
    EXPECT_EQ(TopIds(ranked, expected4.size()), expected4) << "image " << i;
    for (const ImageScore& s : ranked) EXPECT_NE(s.image_id, images.ids[i]);
  }

  // The matrix is symmetric, has the self-scores on its diagonal and equals the query scores
  // up to rounding.
  const Eigen::MatrixXf similarity = database.SimilarityMatrix();
  ASSERT_EQ(similarity.rows(), 40);
  EXPECT_TRUE((similarity.array() == similarity.transpose().array()).all());
  EXPECT_LT((similarity.diagonal().array() - 1.0f).abs().maxCoeff(), 1e-5f);
  EXPECT_LE(similarity.maxCoeff(), 1.0f + 1e-5f);
  EXPECT_GE(similarity.minCoeff(), 0.0f);
  const auto all = database.QueryAll(0);
  for (int i = 0; i < 40; ++i) {
    const auto ranked = database.Query(images.ids[i], 0);
    ASSERT_EQ(all[i].size(), ranked.size());
    for (const ImageScore& s : ranked) {
      const int j = (s.image_id - 100) / 2;
      EXPECT_NEAR(s.score, similarity(i, j), 1e-6f) << i << " " << j;
    }
    for (const ImageScore& s : all[i]) {
      EXPECT_EQ(s.score, similarity(i, (s.image_id - 100) / 2));
    }
  }
  {
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    EXPECT_TRUE((database.SimilarityMatrix().array() == similarity.array()).all());
  }

  // An image from outside, given by words, finds its twin with score 1.
  const auto outside = database.Query(tree.QuantizeAll(images.descriptors[17]), 3);
  ASSERT_FALSE(outside.empty());
  EXPECT_EQ(outside[0].image_id, images.ids[17]);
  EXPECT_NEAR(outside[0].score, 1.0f, 1e-5f);
}

// 150 images (ids 0 .. 149) over 400 words with P(word w) ~ 1 / (w + 3): the frequent words
// are in most images (the dense product of SimilarityMatrix()), the rare ones in a few (the
// inverted file). Some images get no words.
ImageDatabase ZipfDatabase(TfIdfNorm norm) {
  Random random(13);
  std::vector<double> cdf;
  double total = 0;
  for (int w = 0; w < 400; ++w) cdf.push_back(total += 1.0 / (w + 3));
  ImageDatabase database(400, WithNorm(norm));
  for (image_t i = 0; i < 150; ++i) {
    std::vector<uint32_t> words(random.UniformInt(0, 60));
    for (auto& w : words) {
      w = std::lower_bound(cdf.begin(), cdf.end(), random.UniformReal(0, total)) - cdf.begin();
    }
    database.AddImage(i, words);
  }
  database.Finalize();
  return database;
}

TEST_P(ImageDatabaseNormTest, SimilarityMatrixMatchesBruteForce) {
  const ImageDatabase database = ZipfDatabase(GetParam());
  const Eigen::MatrixXf similarity = database.SimilarityMatrix();
  int dense_words = 0;
  for (uint32_t w = 0; w < 400; ++w) {
    dense_words += database.IdfWeight(w) > 0 && database.IdfWeight(w) < std::log(150.0 / 64);
  }
  EXPECT_GT(dense_words, 3);
  for (image_t i = 0; i < 150; ++i) {
    const auto a = database.ImageVector(i);
    for (image_t j = 0; j < 150; ++j) {
      const auto b = database.ImageVector(j);
      double expected = 0;
      for (size_t p = 0, q = 0; p < a.size() && q < b.size();) {
        if (a[p].first < b[q].first) {
          ++p;
        } else if (b[q].first < a[p].first) {
          ++q;
        } else {
          expected += GetParam() == TfIdfNorm::kL2 ? double{a[p].second} * b[q].second
                                                   : std::min(a[p].second, b[q].second);
          ++p, ++q;
        }
      }
      ASSERT_NEAR(similarity(i, j), expected, 1e-5) << i << " " << j;
    }
  }
  {
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    EXPECT_TRUE((database.SimilarityMatrix().array() == similarity.array()).all());
  }
}

// Relative agreement of a streamed or ranked score with SimilarityMatrix(), whose sums may
// round differently; every term is positive, so the relative error stays near float epsilon.
constexpr float kRelativeTolerance = 1e-5f;

bool NearRelative(float a, float b) {
  return std::abs(a - b) <= kRelativeTolerance * std::max(std::abs(a), std::abs(b));
}

// Checks a candidate list of image `i` against its row of the similarity matrix: the best
// `count` of the positive-scoring images `eligible` (row i of the matrix in index order),
// with near ties at the cut and in the order allowed to go either way.
void ExpectTopOfRow(const std::vector<ScoredIndex>& listed, const Eigen::MatrixXf& similarity,
                    int i, size_t count, const std::function<bool(int)>& eligible) {
  std::vector<int> expected;
  for (int j = 0; j < similarity.rows(); ++j) {
    if (j != i && eligible(j) && similarity(i, j) > 0) expected.push_back(j);
  }
  std::stable_sort(expected.begin(), expected.end(),
                   [&](int a, int b) { return similarity(i, a) > similarity(i, b); });
  ASSERT_EQ(listed.size(), std::min(count, expected.size())) << "image " << i;
  if (listed.empty()) return;
  const float cut = similarity(i, expected[listed.size() - 1]);
  const float tolerance = kRelativeTolerance * cut;
  std::set<int> listed_indices;
  for (size_t k = 0; k < listed.size(); ++k) {
    const ScoredIndex& s = listed[k];
    ASSERT_TRUE(s.index >= 0 && s.index < similarity.rows() && s.index != i && eligible(s.index))
        << "image " << i << " lists " << s.index;
    EXPECT_TRUE(NearRelative(s.score, similarity(i, s.index))) << i << " " << s.index;
    EXPECT_GE(similarity(i, s.index), cut - tolerance) << i << " " << s.index;
    listed_indices.insert(s.index);
    if (k > 0) {  // exact order on the listed scores, near-tie order against the matrix
      const ScoredIndex& previous = listed[k - 1];
      EXPECT_TRUE(previous.score > s.score ||
                  (previous.score == s.score && previous.index < s.index))
          << "image " << i << " position " << k;
      EXPECT_GE(similarity(i, previous.index), similarity(i, s.index) * (1 - kRelativeTolerance));
    }
  }
  for (const int j : expected) {
    if (similarity(i, j) > cut + tolerance) {
      EXPECT_TRUE(listed_indices.count(j)) << i << " " << j;
    }
  }
}

TEST_P(ImageDatabaseNormTest, CandidatesAgreeWithSimilarityMatrix) {
  const ImageDatabase database = ZipfDatabase(GetParam());
  const Eigen::MatrixXf similarity = database.SimilarityMatrix();
  const int n = database.NumImages();
  constexpr int kNumBest = 5, kNumFar = 3, kGap = 10;
  const SimilarityCandidates candidates = database.Candidates(kNumBest, kNumFar, kGap);
  ASSERT_EQ(candidates.best.size(), static_cast<size_t>(n));
  ASSERT_EQ(candidates.far.size(), static_cast<size_t>(n));
  int num_empty = 0;
  for (int i = 0; i < n; ++i) {
    ExpectTopOfRow(candidates.best[i], similarity, i, kNumBest, [](int) { return true; });
    ExpectTopOfRow(candidates.far[i], similarity, i, kNumFar,
                   [&](int j) { return std::abs(i - j) > kGap; });
    num_empty += candidates.best[i].empty();
  }
  EXPECT_GT(num_empty, 0);  // images without weighted words, as the database is built

  // More partners than images: every positive-scoring image, and the same pair scores the same
  // from both sides.
  const SimilarityCandidates all = database.Candidates(n + 10, n + 10, 0);
  for (int i = 0; i < n; ++i) {
    ExpectTopOfRow(all.best[i], similarity, i, n + 10, [](int) { return true; });
    EXPECT_EQ(all.far[i], all.best[i]);  // a gap of 0 leaves out only the image itself
    for (const ScoredIndex& s : all.best[i]) {
      const auto& back = all.best[s.index];
      const auto it = std::find_if(back.begin(), back.end(),
                                   [&](const ScoredIndex& t) { return t.index == i; });
      ASSERT_NE(it, back.end()) << i << " " << s.index;
      EXPECT_EQ(it->score, s.score) << i << " " << s.index;
    }
  }

  // Blocks of images run in parallel; the lists do not depend on how many threads run them.
  // Four threads even on a smaller machine: the arena alone gets no more workers than cores.
  SimilarityCandidates one_thread, four_threads;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 4);
    tbb::task_arena arena(4);
    arena.execute([&] { four_threads = database.Candidates(kNumBest, kNumFar, kGap); });
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one_thread = database.Candidates(kNumBest, kNumFar, kGap);
  }
  EXPECT_EQ(one_thread.best, candidates.best);
  EXPECT_EQ(one_thread.far, candidates.far);
  EXPECT_EQ(four_threads.best, candidates.best);
  EXPECT_EQ(four_threads.far, candidates.far);
}

TEST_P(ImageDatabaseNormTest, ForEachSimilarityRowStreamsTheMatrix) {
  // 150 images: two whole blocks of rows and a partial one.
  const ImageDatabase database = ZipfDatabase(GetParam());
  const Eigen::MatrixXf similarity = database.SimilarityMatrix();
  const int n = database.NumImages();
  const SimilarityCandidates candidates = database.Candidates(n, 0, 0);
  std::vector<int> visited;
  database.ForEachSimilarityRow([&](int row, const float* scores) {
    visited.push_back(row);
    for (int j = 0; j < n; ++j) {
      ASSERT_TRUE(NearRelative(scores[j], similarity(row, j))) << row << " " << j;
    }
    // The same scores as the candidate lists, to the bit.
    for (const ScoredIndex& s : candidates.best[row]) EXPECT_EQ(scores[s.index], s.score);
  });
  std::vector<int> expected(n);
  for (int i = 0; i < n; ++i) expected[i] = i;
  EXPECT_EQ(visited, expected);
}

INSTANTIATE_TEST_SUITE_P(Norms, ImageDatabaseNormTest,
                         ::testing::Values(TfIdfNorm::kL1, TfIdfNorm::kL2), [](const auto& info) {
                           return info.param == TfIdfNorm::kL1 ? "L1" : "L2";
                         });

TEST(ImageDatabase, ImageWithoutWordsScoresZero) {
  ImageDatabase database(5);
  database.AddImage(1, {});
  database.AddImage(2, {1, 2});
  database.AddImage(3, {2, 3});
  database.Finalize();
  EXPECT_TRUE(database.Query(1, 5).empty());
  const Eigen::MatrixXf similarity = database.SimilarityMatrix();
  EXPECT_EQ(similarity(0, 0), 0.0f);
  EXPECT_NEAR(similarity(1, 1), 1.0f, 1e-6f);
  EXPECT_EQ(similarity.row(0).norm(), 0.0f);
}

TEST(ImageDatabase, CandidatesOnlyListImagesThatShareWords) {
  ImageDatabase database(10);
  database.AddImage(1, {});
  database.AddImage(2, {1, 2});
  database.AddImage(3, {2, 3});
  database.AddImage(4, {5});  // a word of its own: weighted, but shared with no image
  database.Finalize();
  const SimilarityCandidates candidates = database.Candidates(3, 3, 0);
  for (const int i : {0, 3}) {
    EXPECT_TRUE(candidates.best[i].empty()) << i;
    EXPECT_TRUE(candidates.far[i].empty()) << i;
  }
  ASSERT_EQ(candidates.best[1].size(), 1u);
  EXPECT_EQ(candidates.best[1][0].index, 2);
  ASSERT_EQ(candidates.best[2].size(), 1u);
  EXPECT_EQ(candidates.best[2][0].index, 1);
  EXPECT_EQ(candidates.far[1], candidates.best[1]);  // a gap of 0 leaves out only the image
  // Images 2 and 3 are neighbours (indices 1 and 2): a gap of 1 leaves them no far partner.
  const SimilarityCandidates gapped = database.Candidates(3, 3, 1);
  EXPECT_EQ(gapped.best, candidates.best);
  for (const auto& far : gapped.far) EXPECT_TRUE(far.empty());
  // The streamed rows still hold the self-scores, 0 for the image without words.
  std::vector<float> diagonal;
  database.ForEachSimilarityRow(
      [&](int row, const float* scores) { diagonal.push_back(scores[row]); });
  ASSERT_EQ(diagonal.size(), 4u);
  EXPECT_EQ(diagonal[0], 0.0f);
  for (int i = 1; i < 4; ++i) EXPECT_NEAR(diagonal[i], 1.0f, 1e-6f);

  ImageDatabase empty(10);
  empty.Finalize();
  EXPECT_TRUE(empty.Candidates(3, 3, 0).best.empty());
  int num_rows = 0;
  empty.ForEachSimilarityRow([&](int, const float*) { ++num_rows; });
  EXPECT_EQ(num_rows, 0);
}

TEST(ImageDatabase, RejectsBadInput) {
  EXPECT_THROW(ImageDatabase(0), InvalidArgument);
  ImageDatabase database(4);
  database.AddImage(1, {0, 3});
  EXPECT_THROW(database.AddImage(1, {1}), InvalidArgument);
  EXPECT_THROW(database.AddImage(2, {4}), InvalidArgument);
  EXPECT_THROW(database.AddImage(kInvalidImageId, {1}), InvalidArgument);
  database.AddImage(2, {1});
  database.Finalize();
  EXPECT_EQ(database.NumImages(), 2);
  EXPECT_THROW(database.Query(3, 1), InvalidArgument);
  EXPECT_THROW(database.Query(std::vector<uint32_t>{0, 9}, 1), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm
