// Descriptor matching: loopsfm's MatchDescriptors (blocked GEMM, exact distances, fused best-2)
// against OpenCV's cv::BFMatcher(NORM_L2).knnMatch(k = 2) + ratio test, on the same
// descriptors, single-threaded each (cv::setNumThreads(1)), as the pipeline runs one pair per
// thread. Also times geometric verification of a synthetic pair.
//
// Descriptors: SIFT (cv::SIFT, RootSIFT-normalised and quantised like COLMAP's) from the first
// two images of the folder in LOOPSFM_BENCH_IMAGES, e.g.
//   LOOPSFM_BENCH_IMAGES=../shared/data/fox/images bench_matching --benchmark_repetitions=5
// otherwise synthetic SIFT-like descriptors (half of image 2 are noisy copies of image 1).
// After the runs, a summary prints ms per pair (median over repetitions when given), pairs per
// second, the speed-up, and how well the two matchers' results agree.
// Then a table of every matching kernel this CPU runs on the same pairs: ms per pair, speed-up
// over the float kernel, and whether the matches are identical.

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "loopsfm/math/random.h"
#include "loopsfm/matching/descriptor_matcher.h"
#include "loopsfm/matching/geometric_verification.h"

namespace loopsfm {
namespace {

constexpr double kRatio = 0.8;

struct PairData {
  FeatureDescriptors d1, d2;
  cv::Mat f1, f2;  // the same descriptors as float, for BFMatcher
  std::string source;
};

// COLMAP's default normalisation: RootSIFT (L1-normalise, square root), then * 512 -> uint8.
FeatureDescriptors Quantize(const cv::Mat& descriptors) {
  FeatureDescriptors out(descriptors.rows, kDescriptorDim);
  for (int i = 0; i < descriptors.rows; ++i) {
    const float* row = descriptors.ptr<float>(i);
    double l1 = 0;
    for (int k = 0; k < kDescriptorDim; ++k) l1 += std::abs(row[k]);
    for (int k = 0; k < kDescriptorDim; ++k) {
      const double v = l1 > 0 ? std::sqrt(std::abs(row[k]) / l1) : 0.0;
      out(i, k) = static_cast<uint8_t>(std::min(255.0, std::round(512.0 * v)));
    }
  }
  return out;
}

cv::Mat ToFloat(const FeatureDescriptors& d) {
  cv::Mat f(static_cast<int>(d.rows()), kDescriptorDim, CV_32F);
  for (int i = 0; i < f.rows; ++i) {
    for (int k = 0; k < kDescriptorDim; ++k) f.at<float>(i, k) = d(i, k);
  }
  return f;
}

std::shared_ptr<PairData> FromImages(const std::string& folder, int num_features) {
  std::vector<std::filesystem::path> images;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    const std::string ext = entry.path().extension().string();
    if (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".JPG") {
      images.push_back(entry.path());
    }
  }
  std::sort(images.begin(), images.end());
  if (images.size() < 2) return nullptr;
  auto data = std::make_shared<PairData>();
  const cv::Ptr<cv::SIFT> sift = cv::SIFT::create(num_features, 3, 0.01);
  FeatureDescriptors* outs[2] = {&data->d1, &data->d2};
  for (int k = 0; k < 2; ++k) {
    const cv::Mat image = cv::imread(images[k].string(), cv::IMREAD_GRAYSCALE);
    if (image.empty()) return nullptr;
    std::vector<cv::KeyPoint> keypoints;
    cv::Mat descriptors;
    sift->detectAndCompute(image, cv::noArray(), keypoints, descriptors);
    *outs[k] = Quantize(descriptors.rowRange(0, std::min(descriptors.rows, num_features)));
  }
  data->source = "SIFT of " + images[0].filename().string() + ", " + images[1].filename().string();
  return data;
}

std::shared_ptr<PairData> Synthetic(int num_features, uint64_t seed) {
  Random random(seed);
  auto descriptor = [&]() {
    Eigen::Matrix<float, 1, kDescriptorDim> d;
    for (int k = 0; k < kDescriptorDim; ++k) d(k) = static_cast<float>(std::pow(random.Normal(), 2));
    return Eigen::Matrix<float, 1, kDescriptorDim>(d.normalized());
  };
  auto quantize = [](const Eigen::Matrix<float, 1, kDescriptorDim>& d, FeatureDescriptors* out,
                     int row) {
    for (int k = 0; k < kDescriptorDim; ++k) {
      (*out)(row, k) = static_cast<uint8_t>(std::min(255.0f, std::round(512.0f * d(k))));
    }
  };
  auto data = std::make_shared<PairData>();
  data->d1.resize(num_features, kDescriptorDim);
  data->d2.resize(num_features, kDescriptorDim);
  const std::vector<uint32_t> order = random.Sample(num_features, num_features);
  for (int i = 0; i < num_features; ++i) {
    const auto d = descriptor();
    quantize(d, &data->d1, i);
    if (i < num_features / 2) {
      Eigen::Matrix<float, 1, kDescriptorDim> noisy = d;
      for (int k = 0; k < kDescriptorDim; ++k) {
        noisy(k) = std::max(0.0f, noisy(k) + static_cast<float>(random.Normal(0, 0.04)));
      }
      quantize(noisy.normalized(), &data->d2, order[i]);
    } else {
      quantize(descriptor(), &data->d2, order[i]);
    }
  }
  data->source = "synthetic SIFT-like descriptors";
  return data;
}

std::vector<std::pair<int, int>> BfMatches(const PairData& data) {
  cv::BFMatcher matcher(cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> knn;
  matcher.knnMatch(data.f1, data.f2, knn, 2);
  std::vector<std::pair<int, int>> matches;
  for (const auto& m : knn) {
    if (m.size() == 2 && m[0].distance < kRatio * m[1].distance) {
      matches.emplace_back(m[0].queryIdx, m[0].trainIdx);
    }
  }
  return matches;
}

DescriptorMatchingOptions SameAsBfOptions() {
  DescriptorMatchingOptions options;
  options.max_ratio = kRatio;
  options.max_distance = 2.0;  // BFMatcher + ratio test has no distance limit
  options.cross_check = false;
  return options;
}

// A calibrated or uncalibrated synthetic pair: 70% true matches, 30% random ones.
struct VerificationData {
  Camera camera;
  FeatureKeypoints keypoints1, keypoints2;
  FeatureMatches matches;
};

VerificationData SyntheticPair(int num_matches, bool calibrated, uint64_t seed) {
  Random random(seed);
  VerificationData data;
  data.camera.model_id = CameraModelId::kPinhole;
  data.camera.width = 1280;
  data.camera.height = 720;
  data.camera.params = {1000, 1000, 640, 360};
  data.camera.has_prior_focal_length = calibrated;
  const Rigid3d cam2_from_cam1(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d(0.1, 1, 0).normalized())),
      Eigen::Vector3d(-0.5, 0.05, 0.1));
  while (static_cast<int>(data.matches.size()) < num_matches) {
    const Eigen::Vector2d p1(random.UniformReal(0, 1280), random.UniformReal(0, 720));
    Eigen::Vector2d p2(random.UniformReal(0, 1280), random.UniformReal(0, 720));
    if (random.UniformReal() < 0.7) {
      const Eigen::Vector3d x = random.UniformReal(4, 10) * data.camera.CamFromImg(p1).homogeneous();
      p2 = data.camera.ImgFromCam(cam2_from_cam1 * x) +
           Eigen::Vector2d(random.Normal(0, 0.7), random.Normal(0, 0.7));
    }
    const point2D_t idx = static_cast<point2D_t>(data.keypoints1.size());
    data.keypoints1.push_back({static_cast<float>(p1.x()), static_cast<float>(p1.y())});
    data.keypoints2.push_back({static_cast<float>(p2.x()), static_cast<float>(p2.y())});
    data.matches.push_back({idx, idx});
  }
  return data;
}

// Console output as usual, plus the median (or only) time of every benchmark, by name.
class SummaryReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& run : runs) {
      const bool median = run.run_type == Run::RT_Aggregate && run.aggregate_name == "median";
      const bool single = run.run_type == Run::RT_Iteration && run.repetitions <= 1;
      if (median || single) {
        real_ms_[run.run_name.function_name] = run.GetAdjustedRealTime();
        cpu_ms_[run.run_name.function_name] = run.GetAdjustedCPUTime();
      }
    }
  }
  double RealMs(const std::string& name) const { return Find(real_ms_, name); }
  double CpuMs(const std::string& name) const { return Find(cpu_ms_, name); }

 private:
  static double Find(const std::map<std::string, double>& map, const std::string& name) {
    const auto it = map.find(name);
    return it == map.end() ? 0.0 : it->second;
  }
  std::map<std::string, double> real_ms_, cpu_ms_;
};

}  // namespace
}  // namespace loopsfm

int main(int argc, char** argv) {
  using namespace loopsfm;
  benchmark::Initialize(&argc, argv);
  cv::setNumThreads(1);
  const char* folder = std::getenv("LOOPSFM_BENCH_IMAGES");
  const std::vector<int> sizes = {2000, 4000, 8000};

  struct Row {
    int requested;
    std::shared_ptr<PairData> data;
    size_t ours = 0, bf = 0, common = 0;
    // Per kernel: whether its matches (cross check, the pipeline's defaults) are identical to
    // the float kernel's, and how many there are.
    std::map<std::string, bool> identical;
    size_t kernel_matches = 0;
  };
  const std::vector<DescriptorKernel> kernels = AvailableDescriptorKernels();
  std::vector<Row> rows;
  for (const int n : sizes) {
    std::shared_ptr<PairData> data = folder ? FromImages(folder, n) : nullptr;
    if (folder && !data) {
      std::fprintf(stderr, "cannot read two images from %s; using synthetic descriptors\n", folder);
    }
    if (!data) data = Synthetic(n, 1000 + n);
    data->f1 = ToFloat(data->d1);
    data->f2 = ToFloat(data->d2);
    // Agreement of the two matchers on this pair, outside the timed loops.
    std::set<std::pair<int, int>> ours;
    for (const FeatureMatch& m : MatchDescriptors(data->d1, data->d2, SameAsBfOptions())) {
      ours.emplace(m.point2D_idx1, m.point2D_idx2);
    }
    const std::vector<std::pair<int, int>> bf = BfMatches(*data);
    size_t common = 0;
    for (const auto& m : bf) common += ours.count(m);
    Row row{n, data, ours.size(), bf.size(), common, {}, 0};
    DescriptorMatchingOptions float_options;
    float_options.kernel = DescriptorKernel::kFloat;
    const FeatureMatches float_matches = MatchDescriptors(data->d1, data->d2, float_options);
    row.kernel_matches = float_matches.size();
    for (const DescriptorKernel kernel : kernels) {
      DescriptorMatchingOptions options;
      options.kernel = kernel;
      row.identical[DescriptorKernelName(kernel)] =
          MatchDescriptors(data->d1, data->d2, options) == float_matches;
    }
    rows.push_back(std::move(row));

    const std::string size = std::to_string(n);
    benchmark::RegisterBenchmark(("match/loopsfm/" + size).c_str(), [data](benchmark::State& state) {
      const DescriptorMatchingOptions options = SameAsBfOptions();
      for (auto _ : state) benchmark::DoNotOptimize(MatchDescriptors(data->d1, data->d2, options));
      state.counters["pairs_per_s"] = benchmark::Counter(state.iterations(), benchmark::Counter::kIsRate);
    })->Unit(benchmark::kMillisecond)->UseRealTime();
    benchmark::RegisterBenchmark(("match/loopsfm_cross_check/" + size).c_str(),
                                 [data](benchmark::State& state) {
      const DescriptorMatchingOptions options;  // defaults: cross check, max distance 0.7
      for (auto _ : state) benchmark::DoNotOptimize(MatchDescriptors(data->d1, data->d2, options));
      state.counters["pairs_per_s"] = benchmark::Counter(state.iterations(), benchmark::Counter::kIsRate);
    })->Unit(benchmark::kMillisecond)->UseRealTime();
    // Every kernel this CPU runs, cross check as the pipeline's defaults.
    for (const DescriptorKernel kernel : kernels) {
      const std::string name = "match/kernel/" + DescriptorKernelName(kernel) + "/" + size;
      benchmark::RegisterBenchmark(name.c_str(), [data, kernel](benchmark::State& state) {
        DescriptorMatchingOptions options;
        options.kernel = kernel;
        for (auto _ : state) benchmark::DoNotOptimize(MatchDescriptors(data->d1, data->d2, options));
        state.counters["pairs_per_s"] = benchmark::Counter(state.iterations(), benchmark::Counter::kIsRate);
      })->Unit(benchmark::kMillisecond)->UseRealTime();
    }
    benchmark::RegisterBenchmark(("match/opencv_bf/" + size).c_str(), [data](benchmark::State& state) {
      for (auto _ : state) benchmark::DoNotOptimize(BfMatches(*data));
      state.counters["pairs_per_s"] = benchmark::Counter(state.iterations(), benchmark::Counter::kIsRate);
    })->Unit(benchmark::kMillisecond)->UseRealTime();
  }
  for (const bool calibrated : {true, false}) {
    const std::string name = std::string("verify/") + (calibrated ? "calibrated" : "uncalibrated") + "/2000";
    auto data = std::make_shared<VerificationData>(SyntheticPair(2000, calibrated, 7));
    benchmark::RegisterBenchmark(name.c_str(), [data](benchmark::State& state) {
      const TwoViewVerificationOptions options;
      for (auto _ : state) {
        Random random(1);
        benchmark::DoNotOptimize(VerifyTwoViewGeometry(data->camera, data->keypoints1, data->camera,
                                                       data->keypoints2, data->matches, options,
                                                       random));
      }
    })->Unit(benchmark::kMillisecond)->UseRealTime();
  }

  SummaryReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);

  std::printf("\nDescriptors: %s. Times in ms per pair (wall clock; CPU time in brackets),\n"
              "median over repetitions when --benchmark_repetitions is given.\n",
              rows.front().data->source.c_str());
  std::printf("Kernel: %s (auto).\n", DescriptorKernelName(FastestDescriptorKernel()).c_str());
  std::printf("%-10s %-18s %-18s %-18s %-14s %-9s %-19s %-16s %s\n", "features", "loopsfm",
              "loopsfm+xcheck", "opencv_bf", "pairs/s ours", "bf",
              "speed-up wall/cpu", "matches ours/bf", "agree");
  for (const Row& row : rows) {
    const std::string size = std::to_string(row.requested);
    auto cell = [&](const std::string& name) {
      char text[64];
      std::snprintf(text, sizeof(text), "%.2f (%.2f)", reporter.RealMs(name), reporter.CpuMs(name));
      return std::string(text);
    };
    const double ours = reporter.RealMs("match/loopsfm/" + size);
    const double bf = reporter.RealMs("match/opencv_bf/" + size);
    if (ours <= 0 || bf <= 0) continue;  // filtered out
    const std::string features =
        std::to_string(row.data->d1.rows()) + "x" + std::to_string(row.data->d2.rows());
    const std::string counts = std::to_string(row.ours) + "/" + std::to_string(row.bf);
    char speedup[64];
    std::snprintf(speedup, sizeof(speedup), "%.1fx / %.1fx", bf / ours,
                  reporter.CpuMs("match/opencv_bf/" + size) /
                      reporter.CpuMs("match/loopsfm/" + size));
    std::printf("%-10s %-18s %-18s %-18s %-14.1f %-9.1f %-19s %-16s %.2f%%\n",
                features.c_str(), cell("match/loopsfm/" + size).c_str(),
                cell("match/loopsfm_cross_check/" + size).c_str(),
                cell("match/opencv_bf/" + size).c_str(), 1000.0 / ours, 1000.0 / bf,
                speedup, counts.c_str(),
                100.0 * row.common / std::max<size_t>(1, std::max(row.ours, row.bf)));
  }
  std::printf("agree: matches found by both / the larger count. Both matchers single-threaded.\n");

  // Every kernel on the same pairs: ms per pair, speed-up over the float kernel, and whether
  // the matches are identical to the float kernel's.
  std::printf("\nKernels (cross check, max distance 0.7): ms per pair, speed-up over float, "
              "identical matches\n%-14s", "kernel");
  for (const Row& row : rows) {
    const std::string features =
        std::to_string(row.data->d1.rows()) + "x" + std::to_string(row.data->d2.rows());
    std::printf(" %-28s", features.c_str());
  }
  std::printf("\n");
  for (const DescriptorKernel kernel : kernels) {
    const std::string name = DescriptorKernelName(kernel);
    std::printf("%-14s", name.c_str());
    for (const Row& row : rows) {
      const std::string size = std::to_string(row.requested);
      const double ms = reporter.RealMs("match/kernel/" + name + "/" + size);
      const double float_ms = reporter.RealMs("match/kernel/float/" + size);
      char cell[64];
      std::snprintf(cell, sizeof(cell), "%.2f  %.1fx  %s", ms, ms > 0 ? float_ms / ms : 0.0,
                    row.identical.at(name) ? "identical" : "DIFFERENT");
      std::printf(" %-28s", cell);
    }
    std::printf("\n");
  }
  benchmark::Shutdown();
  return 0;
}
