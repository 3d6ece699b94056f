// Retrieval micro-benchmarks, side by side in one run:
//  - SimilarityMatrix (L1 and L2 scores; frequent words through a dense product, the others
//    through the inverted file) against Eigen's sparse-sparse product V V^T of the same L2
//    normalised TF-IDF vectors, for
//    n images of 8000 words each over 65536 words with Zipf-like word frequencies (real
//    vocabularies have a few very common words);
//  - Quantize: descriptors per second through 10 x 5 and 64 x 3 trees (trained on 500k
//    synthetic SIFT-like descriptors), one descriptor at a time against QuantizeAll's grouped
//    descent, per image and for 16 images at once.
//
//   bench_retrieval [--benchmark_filter=Similarity]

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <vector>

#include <Eigen/SparseCore>
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

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
      w = static_cast<uint32_t>(
          std::lower_bound(cdf.begin(), cdf.end(), random.UniformReal(0, total)) - cdf.begin());
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
  const ImageDatabase& database = Database(static_cast<int>(state.range(0)),
                                           state.range(1) == 1 ? TfIdfNorm::kL1 : TfIdfNorm::kL2);
  for (auto _ : state) benchmark::DoNotOptimize(database.SimilarityMatrix());
  state.counters["nnz_per_image"] = static_cast<double>(database.ImageVector(0).size());
}

void BM_SimilarityMatrixEigenSparse(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const ImageDatabase& database = Database(n);
  std::vector<Eigen::Triplet<float>> triplets;
  for (int i = 0; i < n; ++i) {
    for (const auto& [word, weight] : database.ImageVector(i))
      triplets.emplace_back(i, word, weight);
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
    for (int k = 0; k < kDescriptorDim; ++k)
      d(k) = static_cast<float>(std::pow(random.Normal(), 2));
    d.normalize();
    for (int k = 0; k < kDescriptorDim; ++k) {
      out(i, k) = static_cast<uint8_t>(std::min(255.0f, std::round(512.0f * d(k))));
    }
  }
  return out;
}

// 16 images of 4000 descriptors through a tree of shape k x L, on one thread: Quantize per
// descriptor (mode 0), QuantizeAll per image (mode 1), QuantizeAll of all 16 at once (mode 2).
void BM_Quantize(benchmark::State& state) {
  static std::map<std::pair<int, int>, std::unique_ptr<VocabularyTree>> trees;
  const int k = static_cast<int>(state.range(0)), depth = static_cast<int>(state.range(1));
  const int mode = static_cast<int>(state.range(2));
  auto& tree = trees[{k, depth}];
  if (!tree) {
    VocabTreeOptions options;
    options.branching = k;
    options.depth = depth;
    options.max_training_descriptors = 500000;
    options.kmeans_iterations = 3;
    Random random(3);
    tree = std::make_unique<VocabularyTree>(
        VocabularyTree::Train(SiftLike(500000, 1), options, random));
  }
  std::vector<FeatureDescriptors> images;
  std::vector<const FeatureDescriptors*> pointers;
  for (int i = 0; i < 16; ++i) images.push_back(SiftLike(4000, 100 + i));
  for (const auto& image : images) pointers.push_back(&image);
  tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  for (auto _ : state) {
    if (mode == 0) {
      for (const auto& image : images) {
        for (int64_t r = 0; r < image.rows(); ++r) {
          benchmark::DoNotOptimize(tree->Quantize(image.row(r).data()));
        }
      }
    } else if (mode == 1) {
      for (const auto& image : images) benchmark::DoNotOptimize(tree->QuantizeAll(image));
    } else {
      benchmark::DoNotOptimize(tree->QuantizeAll(pointers));
    }
  }
  state.SetItemsProcessed(state.iterations() * 16 * 4000);
  state.counters["words"] = tree->NumWords();
}

BENCHMARK(BM_Quantize)
    ->ArgNames({"k", "L", "mode"})
    ->ArgsProduct({{10}, {5}, {0, 1, 2}})
    ->ArgsProduct({{64}, {3}, {0, 1, 2}})
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace loopsfm

BENCHMARK_MAIN();
