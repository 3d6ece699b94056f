// Retrieval micro-benchmarks, side by side in one run:
//  - SimilarityMatrix (L1 and L2 scores; frequent words through a dense product, the others
//    through the inverted file) against Eigen's sparse-sparse product V V^T of the same L2
//    normalised TF-IDF vectors, for
//    n images of 8000 words each over 65536 words with Zipf-like word frequencies (real
//    vocabularies have a few very common words);
//  - Quantize: descriptors per second through trees of different shapes (k x L), trained on
//    synthetic SIFT-like descriptors.
//
//   bench_retrieval [--benchmark_filter=Similarity]

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <vector>

#include <Eigen/SparseCore>

#include "loopsfm/math/random.h"
#include "loopsfm/retrieval/image_database.h"
#include "loopsfm/retrieval/vocabulary_tree.h"

namespace loopsfm {
namespace {

constexpr int kNumWords = 65536;
constexpr int kWordsPerImage = 8000;

// Word lists with P(word w) proportional to 1 / (w + 10).
std::vector<std::vector<uint32_t>> ZipfImages(int num_images, uint64_t seed) {
  std::vector<double> cdf(kNumWords);
  double total = 0;
  for (int w = 0; w < kNumWords; ++w) cdf[w] = (total += 1.0 / (w + 10));
  Random random(seed);
  std::vector<std::vector<uint32_t>> images(num_images);
  for (auto& words : images) {
    words.resize(kWordsPerImage);
    for (auto& w : words) {
      w = static_cast<uint32_t>(std::lower_bound(cdf.begin(), cdf.end(), random.UniformReal(0, total)) -
                                cdf.begin());
      w = std::min<uint32_t>(w, kNumWords - 1);
    }
  }
  return images;
}

const ImageDatabase& Database(int num_images, TfIdfNorm norm = TfIdfNorm::kL2) {
  static std::map<std::pair<int, TfIdfNorm>, std::unique_ptr<ImageDatabase>> cache;
  auto& database = cache[{num_images, norm}];
  if (!database) {
    ImageDatabaseOptions options;
    options.norm = norm;
    database = std::make_unique<ImageDatabase>(kNumWords, options);
    const auto images = ZipfImages(num_images, 17);
    for (int i = 0; i < num_images; ++i) database->AddImage(i, images[i]);
    database->Finalize();
  }
  return *database;
}

void BM_SimilarityMatrix(benchmark::State& state) {
  const ImageDatabase& database = Database(
      static_cast<int>(state.range(0)), state.range(1) == 1 ? TfIdfNorm::kL1 : TfIdfNorm::kL2);
  for (auto _ : state) benchmark::DoNotOptimize(database.SimilarityMatrix());
  state.counters["nnz_per_image"] = static_cast<double>(database.ImageVector(0).size());
}

void BM_SimilarityMatrixEigenSparse(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const ImageDatabase& database = Database(n);
  std::vector<Eigen::Triplet<float>> triplets;
  for (int i = 0; i < n; ++i) {
    for (const auto& [word, weight] : database.ImageVector(i)) triplets.emplace_back(i, word, weight);
  }
  Eigen::SparseMatrix<float, Eigen::RowMajor> vectors(n, kNumWords);
  vectors.setFromTriplets(triplets.begin(), triplets.end());
  const Eigen::SparseMatrix<float, Eigen::ColMajor> transposed = vectors.transpose();
  for (auto _ : state) {
    const Eigen::SparseMatrix<float, Eigen::RowMajor> product = vectors * transposed;
    benchmark::DoNotOptimize(Eigen::MatrixXf(product));
  }
}

BENCHMARK(BM_SimilarityMatrix)
    ->ArgNames({"n", "L"})
    ->ArgsProduct({{250, 1000}, {1, 2}})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimilarityMatrixEigenSparse)->Arg(250)->Arg(1000)->Unit(benchmark::kMillisecond);

// SIFT-like descriptors: squared Gaussians, L2-normalised, * 512 (RootSIFT values are square
// roots of a distribution, so their squares are what sums to one).
FeatureDescriptors SiftLike(int count, uint64_t seed) {
  Random random(seed);
  FeatureDescriptors out(count, kDescriptorDim);
  for (int i = 0; i < count; ++i) {
    Eigen::Matrix<float, kDescriptorDim, 1> d;
    for (int k = 0; k < kDescriptorDim; ++k) d(k) = static_cast<float>(std::pow(random.Normal(), 2));
    d.normalize();
    for (int k = 0; k < kDescriptorDim; ++k) {
      out(i, k) = static_cast<uint8_t>(std::min(255.0f, std::round(512.0f * d(k))));
    }
  }
  return out;
}

void BM_QuantizeAll(benchmark::State& state) {
  static std::map<std::pair<int, int>, std::unique_ptr<VocabularyTree>> trees;
  const int k = static_cast<int>(state.range(0)), depth = static_cast<int>(state.range(1));
  auto& tree = trees[{k, depth}];
  if (!tree) {
    VocabTreeOptions options;
    options.branching = k;
    options.depth = depth;
    options.max_training_descriptors = 100000;
    options.kmeans_iterations = 5;
    Random random(3);
    tree = std::make_unique<VocabularyTree>(
        VocabularyTree::Train(SiftLike(100000, 1), options, random));
  }
  const FeatureDescriptors descriptors = SiftLike(kWordsPerImage, 2);
  for (auto _ : state) benchmark::DoNotOptimize(tree->QuantizeAll(descriptors));
  state.SetItemsProcessed(state.iterations() * descriptors.rows());
  state.counters["words"] = tree->NumWords();
}

BENCHMARK(BM_QuantizeAll)
    ->Args({10, 4})
    ->Args({10, 5})
    ->Args({32, 3})
    ->Args({64, 2})
    ->Args({100, 2})
    ->Args({256, 2})
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace loopsfm

BENCHMARK_MAIN();
