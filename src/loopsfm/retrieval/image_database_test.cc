#include "loopsfm/retrieval/image_database.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

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

TEST_P(ImageDatabaseNormTest, SimilarityMatrixMatchesBruteForce) {
  // 150 images over 400 words with P(word w) ~ 1 / (w + 3): the frequent words are in most
  // images (the dense product), the rare ones in a few (the inverted file).
  Random random(13);
  std::vector<double> cdf;
  double total = 0;
  for (int w = 0; w < 400; ++w) cdf.push_back(total += 1.0 / (w + 3));
  ImageDatabase database(400, WithNorm(GetParam()));
  for (image_t i = 0; i < 150; ++i) {
    std::vector<uint32_t> words(random.UniformInt(0, 60));
    for (auto& w : words) {
      w = std::lower_bound(cdf.begin(), cdf.end(), random.UniformReal(0, total)) - cdf.begin();
    }
    database.AddImage(i, words);
  }
  database.Finalize();
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
