#include "loopsfm/matching/descriptor_matcher.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <thread>

#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using FloatDescriptor = Eigen::Matrix<float, 1, kDescriptorDim>;

// A SIFT-like descriptor: non-negative, a few dominant bins, unit length.
FloatDescriptor RandomDescriptor(Random& random) {
  FloatDescriptor d;
  for (int k = 0; k < kDescriptorDim; ++k) {
    const double g = random.Normal();
    d(k) = static_cast<float>(g * g);
  }
  return d.normalized();
}

// COLMAP's quantisation: value * 512, clamped to 255.
void Quantize(const FloatDescriptor& d, FeatureDescriptors* out, int row) {
  for (int k = 0; k < kDescriptorDim; ++k) {
    (*out)(row, k) = static_cast<uint8_t>(std::clamp(std::round(512.0f * d(k)), 0.0f, 255.0f));
  }
}

FloatDescriptor AddNoise(const FloatDescriptor& d, double sigma, Random& random) {
  FloatDescriptor noisy = d;
  for (int k = 0; k < kDescriptorDim; ++k) {
    noisy(k) = std::max(0.0f, noisy(k) + static_cast<float>(random.Normal(0, sigma)));
  }
  return noisy.normalized();
}

FeatureDescriptors RandomDescriptors(int n, Random& random) {
  FeatureDescriptors out(n, kDescriptorDim);
  for (int i = 0; i < n; ++i) Quantize(RandomDescriptor(random), &out, i);
  return out;
}

int64_t SquaredDistance(const FeatureDescriptors& a, int i, const FeatureDescriptors& b, int j) {
  int64_t sum = 0;
  for (int k = 0; k < kDescriptorDim; ++k) {
    const int64_t diff = static_cast<int64_t>(a(i, k)) - b(j, k);
    sum += diff * diff;
  }
  return sum;
}

// Brute-force reference: best (lowest index on ties) and second-best squared distance.
struct Reference {
  std::vector<int> index;
  std::vector<int64_t> best, second;
};
Reference BruteForce(const FeatureDescriptors& a, const FeatureDescriptors& b) {
  Reference ref;
  for (int i = 0; i < a.rows(); ++i) {
    int64_t best = std::numeric_limits<int64_t>::max(), second = best;
    int best_j = -1;
    for (int j = 0; j < b.rows(); ++j) {
      const int64_t d = SquaredDistance(a, i, b, j);
      if (d < best) {
        second = best;
        best = d;
        best_j = j;
      } else if (d < second) {
        second = d;
      }
    }
    ref.index.push_back(best_j);
    ref.best.push_back(best);
    ref.second.push_back(second);
  }
  return ref;
}

// Reference matcher: ratio test on L2 distances, max distance, optional cross check.
FeatureMatches ReferenceMatches(const FeatureDescriptors& a, const FeatureDescriptors& b,
                                const DescriptorMatchingOptions& options) {
  const Reference ab = BruteForce(a, b), ba = BruteForce(b, a);
  auto passes = [&](int64_t best, int64_t second) {
    const double d1 = std::sqrt(static_cast<double>(best)) / 512.0;
    const double d2 = second == std::numeric_limits<int64_t>::max()
                          ? std::numeric_limits<double>::infinity()
                          : std::sqrt(static_cast<double>(second)) / 512.0;
    return (options.max_distance >= 2.0 || d1 <= options.max_distance) &&
           d1 < options.max_ratio * d2;
  };
  FeatureMatches matches;
  for (int i = 0; i < a.rows(); ++i) {
    const int j = ab.index[i];
    if (j < 0 || !passes(ab.best[i], ab.second[i])) continue;
    if (options.cross_check && (ba.index[j] != i || !passes(ba.best[j], ba.second[j]))) continue;
    matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(j)});
  }
  return matches;
}

// Image 2 holds noisy copies of the first num_shared descriptors of image 1 in shuffled order,
// plus distractors; truth[i] is the row of i's copy in image 2, or -1.
struct PermutedSet {
  FeatureDescriptors d1, d2;
  std::vector<int> truth;
};
PermutedSet MakePermutedSet(int n1, int num_shared, int num_distractors, double noise,
                            Random& random) {
  PermutedSet set;
  std::vector<FloatDescriptor> originals;
  set.d1.resize(n1, kDescriptorDim);
  for (int i = 0; i < n1; ++i) {
    originals.push_back(RandomDescriptor(random));
    Quantize(originals.back(), &set.d1, i);
  }
  const int n2 = num_shared + num_distractors;
  const std::vector<uint32_t> rows = random.Sample(n2, n2);  // a random permutation
  set.d2.resize(n2, kDescriptorDim);
  set.truth.assign(n1, -1);
  for (int i = 0; i < num_shared; ++i) {
    Quantize(AddNoise(originals[i], noise, random), &set.d2, rows[i]);
    set.truth[i] = rows[i];
  }
  for (int k = num_shared; k < n2; ++k) Quantize(RandomDescriptor(random), &set.d2, rows[k]);
  return set;
}

void ExpectAgreesWithBruteForce(const FeatureDescriptors& d1, const FeatureDescriptors& d2,
                                DescriptorKernel kernel) {
  const int n1 = static_cast<int>(d1.rows()), n2 = static_cast<int>(d2.rows());
  const NearestNeighbors nn = FindNearestNeighbors(d1, d2, kernel);
  const Reference ref = BruteForce(d1, d2);
  ASSERT_EQ(nn.index.size(), static_cast<size_t>(n1));
  for (int i = 0; i < n1; ++i) {
    ASSERT_EQ(nn.index[i], ref.index[i]) << "row " << i << " of " << n1 << "x" << n2;
    ASSERT_EQ(nn.best_distance[i], static_cast<float>(ref.best[i]));
    if (n2 == 1) {
      ASSERT_TRUE(std::isinf(nn.second_distance[i]));
    } else {
      ASSERT_EQ(nn.second_distance[i], static_cast<float>(ref.second[i]));
    }
  }
}

// Every kernel this CPU runs (the float one always; AVX2 and AVX-512 VNNI on x86-64, NEON on
// ARM, where the CPU has them).
std::vector<DescriptorKernel> KernelsToTest() {
  std::vector<DescriptorKernel> kernels = AvailableDescriptorKernels();
  std::string names;
  for (const DescriptorKernel k : kernels) names.append(" ").append(DescriptorKernelName(k));
  std::printf("note: kernels tested on this CPU:%s\n", names.c_str());
  return kernels;
}

// d1 against d2 and d2 against d1, with every kernel.
void ExpectEveryKernelAgreesBothWays(const FeatureDescriptors& d1, const FeatureDescriptors& d2) {
  for (const DescriptorKernel kernel : KernelsToTest()) {
    SCOPED_TRACE(DescriptorKernelName(kernel));
    ExpectAgreesWithBruteForce(d1, d2, kernel);
    ExpectAgreesWithBruteForce(d2, d1, kernel);
  }
}

TEST(DescriptorKernels, FloatIsAlwaysAvailableAndAutoRunsTheFastest) {
  const std::vector<DescriptorKernel> kernels = AvailableDescriptorKernels();
  ASSERT_FALSE(kernels.empty());
  EXPECT_EQ(kernels.back(), DescriptorKernel::kFloat);
  EXPECT_EQ(FastestDescriptorKernel(), kernels.front());
  EXPECT_TRUE(DescriptorKernelAvailable(DescriptorKernel::kAuto));
#if defined(__x86_64__)
  EXPECT_FALSE(DescriptorKernelAvailable(DescriptorKernel::kNeon));
#endif
}

TEST(DescriptorKernels, NamesRoundTripAndUnknownOrUnavailableOnesAreRefused) {
  for (const DescriptorKernel k :
       {DescriptorKernel::kAuto, DescriptorKernel::kFloat, DescriptorKernel::kAvx2,
        DescriptorKernel::kAvx512Vnni, DescriptorKernel::kNeon, DescriptorKernel::kNeonDotprod}) {
    EXPECT_EQ(ParseDescriptorKernel(DescriptorKernelName(k)), k);
  }
  EXPECT_THROW(ParseDescriptorKernel("sse9"), InvalidArgument);
  for (const DescriptorKernel k : {DescriptorKernel::kAvx2, DescriptorKernel::kAvx512Vnni,
                                   DescriptorKernel::kNeon, DescriptorKernel::kNeonDotprod}) {
    if (DescriptorKernelAvailable(k)) continue;
    DescriptorMatchingOptions options;
    options.kernel = k;
    EXPECT_THROW(options.Check(), InvalidArgument) << DescriptorKernelName(k);
  }
}

TEST(FindNearestNeighbors, EveryKernelAgreesExactlyWithBruteForce) {
  for (const DescriptorKernel kernel : KernelsToTest()) {
    SCOPED_TRACE(DescriptorKernelName(kernel));
    Random random(7);
    // Sizes that span several GEMM row and column blocks and are not multiples of the lanes
    // (nor of the integer kernels' 2 or 4 rows and 32 columns).
    for (const auto& [n1, n2] : {std::pair{1, 1}, {3, 2}, {600, 1500}, {257, 1041}, {5, 33}}) {
      // Half of image 1 is a noisy copy of image 2, so near and far neighbours both occur.
      const FeatureDescriptors d2 = RandomDescriptors(n2, random);
      FeatureDescriptors d1 = RandomDescriptors(n1, random);
      for (int i = 0; i < n1 / 2; ++i) d1.row(i) = d2.row(i % n2);
      ExpectAgreesWithBruteForce(d1, d2, kernel);
    }
  }
}

// Bytes over the whole 0..255 range, all-0 and all-255 rows included: the largest dot
// products and norms the integer and float arithmetic must hold exactly.
TEST(FindNearestNeighbors, EveryKernelIsExactOverTheFullByteRange) {
  Random random(17);
  auto random_bytes = [&](int n) {
    FeatureDescriptors d(n, kDescriptorDim);
    for (int i = 0; i < n; ++i) {
      for (int k = 0; k < kDescriptorDim; ++k) d(i, k) = static_cast<uint8_t>(random.UniformInt(0, 255));
    }
    d.row(0).setConstant(255);
    d.row(1).setZero();
    return d;
  };
  ExpectEveryKernelAgreesBothWays(random_bytes(70), random_bytes(45));
}

// Mostly bytes below 128 with a byte of 128..255 in some rows, so blocks of rows with and
// without one sit side by side (the AVX2 kernel splits only the latter), remainder rows
// included; image 2 has a column of all 255 and one of all 0 (b - 128 at both ends).
TEST(FindNearestNeighbors, EveryKernelIsExactWithAFewLargeBytes) {
  Random random(23);
  auto bytes = [&](int n, int every) {
    FeatureDescriptors d(n, kDescriptorDim);
    for (int i = 0; i < n; ++i) {
      for (int k = 0; k < kDescriptorDim; ++k) d(i, k) = static_cast<uint8_t>(random.UniformInt(0, 127));
      if (i % every == 3) d(i, random.UniformInt(0, kDescriptorDim - 1)) = static_cast<uint8_t>(random.UniformInt(128, 255));
    }
    return d;
  };
  const FeatureDescriptors d1 = bytes(263, 7);
  FeatureDescriptors d2 = bytes(97, 5);
  d2.row(10).setConstant(255);
  d2.row(11).setZero();
  d2.row(12).setConstant(128);
  ExpectEveryKernelAgreesBothWays(d1, d2);
}

// Large bytes (128..255) at the same few places in rows and columns, in rows and columns of one
// block and of several, next to rows and columns that have none: the AVX2 kernel splits the
// rows' bytes above 127 off, and a kernel that split the columns' too would have to add back
// where the two meet.
TEST(FindNearestNeighbors, EveryKernelIsExactWhereLargeBytesMeet) {
  Random random(29);
  const std::vector<int> places = {0, 5, 6, 63, 64, 127};
  auto bytes = [&](int n, int every) {
    FeatureDescriptors d(n, kDescriptorDim);
    for (int i = 0; i < n; ++i) {
      for (int k = 0; k < kDescriptorDim; ++k) d(i, k) = static_cast<uint8_t>(random.UniformInt(0, 127));
      if (i % every != 0) continue;
      for (int p : places) {
        if (random.UniformInt(0, 1) == 1) d(i, p) = static_cast<uint8_t>(random.UniformInt(128, 255));
      }
    }
    return d;
  };
  ExpectEveryKernelAgreesBothWays(bytes(131, 2), bytes(77, 3));
}

TEST(MatchDescriptors, AgreesWithReferenceMatcher) {
  Random random(11);
  const PermutedSet set = MakePermutedSet(700, 500, 900, 0.05, random);
  for (const DescriptorKernel kernel : KernelsToTest()) {
    for (const bool cross_check : {false, true}) {
      for (const double max_distance : {0.7, 2.0}) {
        DescriptorMatchingOptions options;
        options.kernel = kernel;
        options.cross_check = cross_check;
        options.max_distance = max_distance;
        EXPECT_EQ(MatchDescriptors(set.d1, set.d2, options),
                  ReferenceMatches(set.d1, set.d2, options))
            << DescriptorKernelName(kernel) << " cross_check " << cross_check << " max_distance "
            << max_distance;
      }
    }
  }
}

TEST(MatchDescriptors, RecoversPermutationWithHighPrecisionAndRecall) {
  Random random(3);
  const int num_shared = 1500;
  const PermutedSet set = MakePermutedSet(2000, num_shared, 500, 0.04, random);
  const FeatureMatches matches = MatchDescriptors(set.d1, set.d2, DescriptorMatchingOptions());
  int correct = 0;
  for (const FeatureMatch& m : matches) correct += set.truth[m.point2D_idx1] == static_cast<int>(m.point2D_idx2);
  const double precision = static_cast<double>(correct) / matches.size();
  const double recall = static_cast<double>(correct) / num_shared;
  EXPECT_GT(precision, 0.99);
  EXPECT_GT(recall, 0.95);
  for (size_t k = 1; k < matches.size(); ++k) {
    EXPECT_LT(matches[k - 1].point2D_idx1, matches[k].point2D_idx1);
  }
}

TEST(MatchDescriptors, RatioTestRemovesAmbiguousMatches) {
  Random random(5);
  const int n = 400;
  std::vector<FloatDescriptor> originals;
  FeatureDescriptors d1(n, kDescriptorDim);
  for (int i = 0; i < n; ++i) {
    originals.push_back(RandomDescriptor(random));
    Quantize(originals.back(), &d1, i);
  }
  // Image 2: one copy of features 0..n/2-1, two near-identical copies of the others.
  FeatureDescriptors d2(n / 2 + 2 * (n - n / 2), kDescriptorDim);
  int row = 0;
  // The two copies are much closer to each other than to the original, so their distances
  // to it differ by far less than the ratio test's margin.
  for (int i = 0; i < n; ++i) {
    const FloatDescriptor copy = AddNoise(originals[i], 0.03, random);
    Quantize(copy, &d2, row++);
    if (i >= n / 2) Quantize(AddNoise(copy, 0.002, random), &d2, row++);
  }
  DescriptorMatchingOptions options;
  options.cross_check = false;
  int unique_matched = 0;
  for (const FeatureMatch& m : MatchDescriptors(d1, d2, options)) {
    EXPECT_LT(m.point2D_idx1, static_cast<point2D_t>(n / 2)) << "ambiguous feature matched";
    ++unique_matched;
  }
  EXPECT_GT(unique_matched, 0.95 * n / 2);
  // A ratio of 1 keeps the nearest copy of the ambiguous features too.
  options.max_ratio = 1.0;
  EXPECT_GT(MatchDescriptors(d1, d2, options).size(), 0.95 * n);
}

TEST(MatchDescriptors, CrossCheckMakesMatchesOneToOne) {
  Random random(9);
  const int n = 300;
  FeatureDescriptors d2 = RandomDescriptors(n, random);
  // Image 1: a noisy copy of every descriptor of image 2, and for the first 100 a second copy
  // very close to the first.
  FeatureDescriptors d1(n + 100, kDescriptorDim);
  for (int j = 0; j < n; ++j) {
    const FloatDescriptor copy = AddNoise(d2.row(j).cast<float>().normalized(), 0.03, random);
    Quantize(copy, &d1, j);
    if (j < 100) Quantize(AddNoise(copy, 0.002, random), &d1, n + j);
  }
  DescriptorMatchingOptions options;
  options.cross_check = false;
  const FeatureMatches one_way = MatchDescriptors(d1, d2, options);
  std::multiset<point2D_t> targets;
  for (const FeatureMatch& m : one_way) targets.insert(m.point2D_idx2);
  int many_to_one = 0;
  for (point2D_t j = 0; j < 100; ++j) many_to_one += targets.count(j) == 2;
  EXPECT_GT(many_to_one, 90);  // both copies find their original

  options.cross_check = true;
  const FeatureMatches mutual = MatchDescriptors(d1, d2, options);
  std::set<point2D_t> unique_targets;
  for (const FeatureMatch& m : mutual) {
    EXPECT_TRUE(unique_targets.insert(m.point2D_idx2).second);
    // Originals with two copies in image 1 fail the reverse ratio test.
    EXPECT_GE(m.point2D_idx2, 100u);
    EXPECT_EQ(m.point2D_idx1, m.point2D_idx2);
  }
  EXPECT_GT(mutual.size(), 0.95 * (n - 100));
}

TEST(MatchDescriptors, MaxDistanceRejectsUnrelatedDescriptors) {
  Random random(13);
  const FeatureDescriptors d1 = RandomDescriptors(200, random);
  const FeatureDescriptors d2 = RandomDescriptors(1, random);  // one candidate: ratio passes
  DescriptorMatchingOptions options;
  options.max_distance = 2.0;
  options.cross_check = false;
  EXPECT_EQ(MatchDescriptors(d1, d2, options).size(), 200u);
  options.max_distance = 0.3;
  EXPECT_TRUE(MatchDescriptors(d1, d2, options).empty());
}

TEST(MatchDescriptors, EmptyInputsAndBadOptions) {
  Random random(1);
  const FeatureDescriptors some = RandomDescriptors(10, random);
  const FeatureDescriptors none(0, kDescriptorDim);
  const DescriptorMatchingOptions options;
  EXPECT_TRUE(MatchDescriptors(none, some, options).empty());
  EXPECT_TRUE(MatchDescriptors(some, none, options).empty());
  EXPECT_TRUE(MatchDescriptors(none, none, options).empty());
  DescriptorMatchingOptions bad;
  bad.max_ratio = 1.5;
  EXPECT_THROW(MatchDescriptors(some, some, bad), InvalidArgument);
  bad.max_ratio = 0.8;
  bad.max_distance = 0.0;
  EXPECT_THROW(bad.Check(), InvalidArgument);
}

TEST(MatchDescriptors, ParallelCallsGiveTheSerialResults) {
  Random random(17);
  std::vector<PermutedSet> sets;
  for (int k = 0; k < 8; ++k) sets.push_back(MakePermutedSet(600, 400, 300, 0.05, random));
  const DescriptorMatchingOptions options;
  std::vector<FeatureMatches> serial, parallel(sets.size());
  for (const PermutedSet& s : sets) serial.push_back(MatchDescriptors(s.d1, s.d2, options));
  // Plain threads, one pair each (the pipeline runs pairs in tbb::parallel_for; std::thread
  // keeps this test free of TBB, so that it also cross-compiles for the NEON kernels).
  std::vector<std::thread> threads;
  for (size_t k = 0; k < sets.size(); ++k) {
    threads.emplace_back([&, k] { parallel[k] = MatchDescriptors(sets[k].d1, sets[k].d2, options); });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(parallel, serial);
}

}  // namespace
}  // namespace loopsfm
