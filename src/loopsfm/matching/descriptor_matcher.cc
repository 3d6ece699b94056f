#include "loopsfm/matching/descriptor_matcher.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#if defined(__aarch64__) && defined(__linux__)
#include <asm/hwcap.h>
#include <sys/auxv.h>
#endif

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "loopsfm/matching/descriptor_kernels.h"
#include "loopsfm/matching/descriptor_search.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

constexpr float kInf = std::numeric_limits<float>::infinity();
using internal::kLanes;

// Float copies of uint8 descriptors, rows padded with zeros to a multiple of `pad`; padded
// rows get an infinite squared norm so that they are never anyone's neighbour.
struct FloatDescriptors {
  RowMatrixXf values;
  std::vector<float> sq_norms;
  int num = 0;
};

FloatDescriptors ToFloat(const FeatureDescriptors& descriptors, int pad) {
  FloatDescriptors f;
  f.num = static_cast<int>(descriptors.rows());
  const int padded = (f.num + pad - 1) / pad * pad;
  f.values.setZero(padded, kDescriptorDim);
  f.values.topRows(f.num) = descriptors.cast<float>();
  f.sq_norms.assign(padded, kInf);
  for (int i = 0; i < f.num; ++i) f.sq_norms[i] = f.values.row(i).squaredNorm();
  return f;
}

// Best and second-best squared distance and the best index, per row or per column.
struct Best2 {
  std::vector<float> d1, d2;
  std::vector<int32_t> idx;
  // Sized for n entries, which the search writes.
  internal::Best2Arrays Arrays(size_t n) {
    d1.resize(n);
    d2.resize(n);
    idx.resize(n);
    return {d1.data(), d2.data(), idx.data()};
  }
};

// The search's scratch memory (1 MB of tile, lanes of a row block).
struct SearchScratchMemory {
  // Every tile entry is written before it is read: no need to zero 1 MB per pair.
  std::unique_ptr<float[]> tile{new float[static_cast<size_t>(internal::kRowBlock) * internal::kColBlock]};
  std::vector<float> lane_best = std::vector<float>(internal::kRowBlock * kLanes);
  std::vector<float> lane_second = std::vector<float>(internal::kRowBlock * kLanes);
  std::vector<int32_t> lane_index = std::vector<int32_t>(internal::kRowBlock * kLanes);
  internal::SearchScratch View() {
    return {tile.get(), lane_best.data(), lane_second.data(), lane_index.data()};
  }
};

// The float kernel: Eigen's GEMM on float copies (exact: every partial sum is an integer
// below 2^24).
template <bool kColumns>
void SearchBest2Float(const FeatureDescriptors& d1, const FeatureDescriptors& d2, Best2* rows,
                      Best2* cols) {
  const FloatDescriptors f1 = ToFloat(d1, 1);
  const FloatDescriptors f2 = ToFloat(d2, kLanes);
  SearchScratchMemory scratch;
  const int n2_padded = static_cast<int>(f2.sq_norms.size());
  internal::SearchBest2<kColumns>(
      f1.num, f1.sq_norms.data(), n2_padded, f2.sq_norms.data(),
      [&](int r0, int num_rows, int c0, int num_cols, float* tile) {
        Eigen::Map<RowMatrixXf> dots(tile, num_rows, num_cols);
        dots.noalias() =
            f1.values.middleRows(r0, num_rows) * f2.values.middleRows(c0, num_cols).transpose();
      },
      scratch.View(), rows->Arrays(f1.num),
      kColumns ? cols->Arrays(n2_padded) : internal::Best2Arrays{});
}

// The integer kernels (descriptor_kernels.h): image 2 packed once per pair, tiles filled by
// the kernel of this CPU's instruction set.
struct IntegerKernel {
  internal::IntegerSearchFn search = nullptr;
  // x86: columns stored as b - 128 (unsigned by signed bytes); ARM: as b.
  bool offset_columns = false;
};

IntegerKernel IntegerKernelFor(DescriptorKernel kernel) {
  switch (kernel) {
#if defined(__x86_64__)
    case DescriptorKernel::kAvx512Vnni: return {internal::SearchAvx512Vnni, true};
    case DescriptorKernel::kAvx2: return {internal::SearchAvx2, true};
#endif
#if defined(__aarch64__)
    case DescriptorKernel::kNeonDotprod: return {internal::SearchNeonDotprod, false};
    case DescriptorKernel::kNeon: return {internal::SearchNeon, false};
#endif
    default: return {};
  }
}

struct PackedColumns {
  std::vector<int8_t> bytes;
  std::vector<float> sq_norms;
};

// Image 2 in the kernels' layout, padded to whole kernel steps with infinite norms.
PackedColumns PackColumns(const FeatureDescriptors& d, bool offset) {
  using internal::kPackedGroup;
  using internal::kPackedGroupBytes;
  const int n = static_cast<int>(d.rows());
  const int step = internal::kKernelColumnStep;
  const int padded = (n + step - 1) / step * step;
  // b - 128 as a signed byte is b with its top bit flipped: 4 bytes at a time.
  const uint32_t flip = offset ? 0x80808080u : 0u;
  PackedColumns packed;
  packed.bytes.assign(static_cast<size_t>(padded) * kDescriptorDim, 0);
  packed.sq_norms.assign(padded, kInf);
  for (int j = 0; j < n; ++j) {
    const uint8_t* row = d.data() + static_cast<size_t>(j) * kDescriptorDim;
    int8_t* group = packed.bytes.data() + static_cast<size_t>(j / kPackedGroup) * kPackedGroupBytes;
    const int lane = j % kPackedGroup;
    for (int q = 0; q < kDescriptorDim / 4; ++q) {
      uint32_t quad;
      std::memcpy(&quad, row + 4 * q, sizeof(quad));
      quad ^= flip;
      std::memcpy(group + q * 64 + lane * 4, &quad, sizeof(quad));
    }
    int32_t sq = 0;
    for (int k = 0; k < kDescriptorDim; ++k) sq += static_cast<int32_t>(row[k]) * row[k];
    packed.sq_norms[j] = static_cast<float>(sq);
  }
  return packed;
}

// The row term that goes with the packed columns: |a|^2, minus 256 sum(a) when they are offset.
std::vector<float> RowTerms(const FeatureDescriptors& d, bool offset) {
  std::vector<float> terms(d.rows());
  for (Eigen::Index i = 0; i < d.rows(); ++i) {
    int32_t sq = 0, sum = 0;
    for (int k = 0; k < kDescriptorDim; ++k) {
      const int32_t v = d(i, k);
      sq += v * v;
      sum += v;
    }
    terms[i] = static_cast<float>(offset ? sq - 256 * sum : sq);
  }
  return terms;
}

void SearchBest2Integer(const FeatureDescriptors& d1, const FeatureDescriptors& d2,
                        const IntegerKernel& kernel, Best2* rows, Best2* cols) {
  static_assert(kDescriptorDim == internal::kKernelDim);
  const PackedColumns packed = PackColumns(d2, kernel.offset_columns);
  const std::vector<float> row_terms = RowTerms(d1, kernel.offset_columns);
  SearchScratchMemory scratch;
  internal::IntegerSearch search;
  search.rows = d1.data();
  search.num_rows = static_cast<int>(d1.rows());
  search.row_terms = row_terms.data();
  search.packed = packed.bytes.data();
  search.num_cols = static_cast<int>(packed.sq_norms.size());
  search.col_norms = packed.sq_norms.data();
  search.scratch = scratch.View();
  search.row_best = rows->Arrays(search.num_rows);
  if (cols != nullptr) search.col_best = cols->Arrays(search.num_cols);
  kernel.search(search);
}

bool CpuRuns(DescriptorKernel kernel) {
  switch (kernel) {
    case DescriptorKernel::kFloat: return true;
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
    case DescriptorKernel::kAvx512Vnni: {
      static const bool has = __builtin_cpu_supports("avx512f") &&
                              __builtin_cpu_supports("avx512bw") &&
                              __builtin_cpu_supports("avx512vnni");
      return has;
    }
    case DescriptorKernel::kAvx2: {
      static const bool has = __builtin_cpu_supports("avx2");
      return has;
    }
#endif
#if defined(__aarch64__)
    case DescriptorKernel::kNeon: return true;  // NEON is part of every ARMv8-A CPU
    case DescriptorKernel::kNeonDotprod: {
#if defined(__linux__)
      static const bool has = (getauxval(AT_HWCAP) & HWCAP_ASIMDDP) != 0;
      return has;
#elif defined(__APPLE__)
      return true;  // every Apple CPU with arm64 has it
#else
      return false;
#endif
    }
#endif
    default: return false;
  }
}

// The kernels, fastest first.
constexpr DescriptorKernel kKernelsByPreference[] = {
    DescriptorKernel::kAvx512Vnni, DescriptorKernel::kAvx2, DescriptorKernel::kNeonDotprod,
    DescriptorKernel::kNeon, DescriptorKernel::kFloat};

std::string UnavailableKernelMessage(DescriptorKernel kernel) {
  std::vector<std::string> names;
  for (const DescriptorKernel k : AvailableDescriptorKernels()) {
    names.push_back(DescriptorKernelName(k));
  }
  return fmt::format("the {} matching kernel does not run on this CPU or was not built for it; "
                     "this machine runs {} (or auto: the fastest)",
                     DescriptorKernelName(kernel), fmt::join(names, ", "));
}

// Best-2 search with the requested kernel (kAuto: the fastest this CPU runs).
template <bool kColumns>
void SearchBest2Any(const FeatureDescriptors& d1, const FeatureDescriptors& d2,
                    DescriptorKernel kernel, Best2* rows, Best2* cols) {
  if (kernel == DescriptorKernel::kAuto) kernel = FastestDescriptorKernel();
  if (!DescriptorKernelAvailable(kernel)) {
    throw InvalidArgument(UnavailableKernelMessage(kernel));
  }
  if (kernel == DescriptorKernel::kFloat) return SearchBest2Float<kColumns>(d1, d2, rows, cols);
  SearchBest2Integer(d1, d2, IntegerKernelFor(kernel), rows, kColumns ? cols : nullptr);
}

}  // namespace

void DescriptorMatchingOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(max_ratio > 0.0 && max_ratio <= 1.0,
                         "matching max_ratio must be in (0, 1], got {}", max_ratio);
  LOOPSFM_REQUIRE_OPTION(max_distance > 0.0,
                         "matching max_distance must be positive (2 disables it), got {}",
                         max_distance);
  if (!DescriptorKernelAvailable(kernel)) throw InvalidArgument(UnavailableKernelMessage(kernel));
}

std::string DescriptorKernelName(DescriptorKernel kernel) {
  switch (kernel) {
    case DescriptorKernel::kAuto: return "auto";
    case DescriptorKernel::kFloat: return "float";
    case DescriptorKernel::kAvx2: return "avx2";
    case DescriptorKernel::kAvx512Vnni: return "avx512-vnni";
    case DescriptorKernel::kNeon: return "neon";
    case DescriptorKernel::kNeonDotprod: return "neon-dotprod";
  }
  return "?";
}

DescriptorKernel ParseDescriptorKernel(const std::string& name) {
  for (const DescriptorKernel k :
       {DescriptorKernel::kAuto, DescriptorKernel::kFloat, DescriptorKernel::kAvx2,
        DescriptorKernel::kAvx512Vnni, DescriptorKernel::kNeon, DescriptorKernel::kNeonDotprod}) {
    if (name == DescriptorKernelName(k)) return k;
  }
  throw InvalidArgument(fmt::format(
      "unknown matching kernel '{}'; choose auto, float, avx2, avx512-vnni, neon or neon-dotprod",
      name));
}

bool DescriptorKernelAvailable(DescriptorKernel kernel) {
  if (kernel == DescriptorKernel::kAuto || kernel == DescriptorKernel::kFloat) return true;
  return IntegerKernelFor(kernel).search != nullptr && CpuRuns(kernel);
}

std::vector<DescriptorKernel> AvailableDescriptorKernels() {
  std::vector<DescriptorKernel> kernels;
  for (const DescriptorKernel k : kKernelsByPreference) {
    if (DescriptorKernelAvailable(k)) kernels.push_back(k);
  }
  return kernels;
}

DescriptorKernel FastestDescriptorKernel() {
  static const DescriptorKernel fastest = AvailableDescriptorKernels().front();
  return fastest;
}

NearestNeighbors FindNearestNeighbors(const FeatureDescriptors& descriptors1,
                                      const FeatureDescriptors& descriptors2,
                                      DescriptorKernel kernel) {
  NearestNeighbors nn;
  const size_t n1 = descriptors1.rows();
  if (descriptors2.rows() == 0) {
    nn.index.assign(n1, -1);
    nn.best_distance.assign(n1, kInf);
    nn.second_distance.assign(n1, kInf);
    return nn;
  }
  Best2 rows;
  SearchBest2Any<false>(descriptors1, descriptors2, kernel, &rows, nullptr);
  nn.index.assign(rows.idx.begin(), rows.idx.end());
  nn.best_distance = std::move(rows.d1);
  nn.second_distance = std::move(rows.d2);
  return nn;
}

FeatureMatches MatchDescriptors(const FeatureDescriptors& descriptors1,
                                const FeatureDescriptors& descriptors2,
                                const DescriptorMatchingOptions& options) {
  options.Check();
  FeatureMatches matches;
  if (descriptors1.rows() == 0 || descriptors2.rows() == 0) return matches;
  const int n1 = static_cast<int>(descriptors1.rows());
  const int n2 = static_cast<int>(descriptors2.rows());
  Best2 rows, cols;
  if (options.cross_check) {
    SearchBest2Any<true>(descriptors1, descriptors2, options.kernel, &rows, &cols);
  } else {
    SearchBest2Any<false>(descriptors1, descriptors2, options.kernel, &rows, nullptr);
  }

  // Squared distances are in uint8 units: a unit-length descriptor has norm 512.
  const double max_sq_distance = options.max_distance >= 2.0
                                     ? std::numeric_limits<double>::infinity()
                                     : (512.0 * options.max_distance) * (512.0 * options.max_distance);
  const double sq_ratio = options.max_ratio * options.max_ratio;
  auto passes = [&](float best, float second) {
    return best <= max_sq_distance && best < sq_ratio * second;
  };

  matches.reserve(std::min(n1, n2));
  for (int i = 0; i < n1; ++i) {
    const int32_t j = rows.idx[i];
    if (j < 0 || !passes(rows.d1[i], rows.d2[i])) continue;
    if (options.cross_check && (cols.idx[j] != i || !passes(cols.d1[j], cols.d2[j]))) continue;
    matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(j)});
  }
  return matches;
}

}  // namespace loopsfm
