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
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

constexpr float kInf = std::numeric_limits<float>::infinity();
// The running best-2 of a row is kept per lane (column index modulo kLanes), so the scan over
// a row of dot products vectorises; the lanes are merged once per row.
constexpr int kLanes = 16;
// GEMM tile: kRowBlock x kColBlock dot products (1 MB) stay in L2 while they are scanned.
constexpr int kRowBlock = 256;
constexpr int kColBlock = 1024;
static_assert(kColBlock % kLanes == 0);

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
  void Init(size_t n) {
    d1.assign(n, kInf);
    d2.assign(n, kInf);
    idx.assign(n, -1);
  }
};

// Updates the best-2 of one row (per lane) and of every column with one tile row of dot
// products. Ties keep the lowest index, as a sequential search would. The lanes are GCC / Clang
// vector-extension types, compiled to one AVX-512 register or two AVX2 ones (or SSE), so the
// row's best-2 stays in registers and each step is a few compare-and-select instructions.
template <bool kColumns>
inline void ScanTileRow(const float* __restrict dots, int num_cols, float a2,
                        const float* __restrict b2, int32_t row_index, int32_t col_offset,
                        float* __restrict lane_d1, float* __restrict lane_d2,
                        int32_t* __restrict lane_idx, float* __restrict c1,
                        float* __restrict c2, int32_t* __restrict ci) {
  using FloatLanes = float __attribute__((vector_size(kLanes * sizeof(float))));
  using IntLanes = int32_t __attribute__((vector_size(kLanes * sizeof(int32_t))));
  FloatLanes l1, l2;
  IntLanes li;
  std::memcpy(&l1, lane_d1, sizeof(l1));
  std::memcpy(&l2, lane_d2, sizeof(l2));
  std::memcpy(&li, lane_idx, sizeof(li));
  IntLanes col_index;
  for (int l = 0; l < kLanes; ++l) col_index[l] = col_offset + l;
  for (int c = 0; c < num_cols; c += kLanes) {
    FloatLanes dot, b;
    std::memcpy(&dot, dots + c, sizeof(dot));
    std::memcpy(&b, b2 + c, sizeof(b));
    const FloatLanes d = a2 + b - 2.0f * dot;
    const IntLanes lt = d < l1;
    l2 = lt ? l1 : (d < l2 ? d : l2);
    li = lt ? col_index : li;
    l1 = lt ? d : l1;
    col_index += kLanes;
    if constexpr (kColumns) {
      FloatLanes cb1, cb2;
      IntLanes cbi;
      std::memcpy(&cb1, c1 + c, sizeof(cb1));
      std::memcpy(&cb2, c2 + c, sizeof(cb2));
      std::memcpy(&cbi, ci + c, sizeof(cbi));
      const IntLanes clt = d < cb1;
      cb2 = clt ? cb1 : (d < cb2 ? d : cb2);
      cbi = clt ? IntLanes{} + row_index : cbi;
      cb1 = clt ? d : cb1;
      std::memcpy(c1 + c, &cb1, sizeof(cb1));
      std::memcpy(c2 + c, &cb2, sizeof(cb2));
      std::memcpy(ci + c, &cbi, sizeof(cbi));
    }
  }
  std::memcpy(lane_d1, &l1, sizeof(l1));
  std::memcpy(lane_d2, &l2, sizeof(l2));
  std::memcpy(lane_idx, &li, sizeof(li));
}

// Exact best-2 search in both directions (columns only when kColumns), tile by tile:
// fill_tile(r0, num_rows, c0, num_cols, tile) writes the num_rows x num_cols dot products
// (row-major) such that row_norms[r] + col_norms[c] - 2 tile(r, c) is the squared distance.
// Columns are padded to a multiple of kLanes with infinite norms.
template <bool kColumns, typename FillTile>
void SearchBest2(int n1, const std::vector<float>& row_norms,
                 const std::vector<float>& col_norms, FillTile&& fill_tile, Best2* rows,
                 Best2* cols) {
  const int n2_padded = static_cast<int>(col_norms.size());
  rows->Init(n1);
  if (kColumns) cols->Init(n2_padded);
  // Every tile entry is written before it is read: no need to zero 1 MB per pair.
  const std::unique_ptr<float[]> tile(new float[static_cast<size_t>(kRowBlock) * kColBlock]);
  std::vector<float> lane_d1(static_cast<size_t>(kRowBlock) * kLanes);
  std::vector<float> lane_d2(lane_d1.size());
  std::vector<int32_t> lane_idx(lane_d1.size());

  for (int r0 = 0; r0 < n1; r0 += kRowBlock) {
    const int num_rows = std::min(kRowBlock, n1 - r0);
    std::fill(lane_d1.begin(), lane_d1.end(), kInf);
    std::fill(lane_d2.begin(), lane_d2.end(), kInf);
    std::fill(lane_idx.begin(), lane_idx.end(), -1);
    for (int c0 = 0; c0 < n2_padded; c0 += kColBlock) {
      const int num_cols = std::min(kColBlock, n2_padded - c0);
      fill_tile(r0, num_rows, c0, num_cols, tile.get());
      for (int r = 0; r < num_rows; ++r) {
        ScanTileRow<kColumns>(tile.get() + static_cast<size_t>(r) * num_cols, num_cols,
                              row_norms[r0 + r], col_norms.data() + c0, r0 + r, c0,
                              lane_d1.data() + r * kLanes, lane_d2.data() + r * kLanes,
                              lane_idx.data() + r * kLanes,
                              kColumns ? cols->d1.data() + c0 : nullptr,
                              kColumns ? cols->d2.data() + c0 : nullptr,
                              kColumns ? cols->idx.data() + c0 : nullptr);
      }
    }
    // Merge the lanes of each row into its best-2.
    for (int r = 0; r < num_rows; ++r) {
      float b1 = kInf, b2 = kInf;
      int32_t bi = -1;
      for (int l = 0; l < kLanes; ++l) {
        const float d = lane_d1[r * kLanes + l];
        const int32_t i = lane_idx[r * kLanes + l];
        if (i >= 0 && (d < b1 || (d == b1 && i < bi))) {
          b2 = std::min(b2, b1);
          b1 = d;
          bi = i;
        } else {
          b2 = std::min(b2, d);
        }
        b2 = std::min(b2, lane_d2[r * kLanes + l]);
      }
      rows->d1[r0 + r] = b1;
      rows->d2[r0 + r] = b2;
      rows->idx[r0 + r] = bi;
    }
  }
}

// The float kernel: Eigen's GEMM on float copies (exact: every partial sum is an integer
// below 2^24).
template <bool kColumns>
void SearchBest2Float(const FeatureDescriptors& d1, const FeatureDescriptors& d2, Best2* rows,
                      Best2* cols) {
  const FloatDescriptors f1 = ToFloat(d1, 1);
  const FloatDescriptors f2 = ToFloat(d2, kLanes);
  SearchBest2<kColumns>(
      f1.num, f1.sq_norms, f2.sq_norms,
      [&](int r0, int num_rows, int c0, int num_cols, float* tile) {
        Eigen::Map<RowMatrixXf> dots(tile, num_rows, num_cols);
        dots.noalias() =
            f1.values.middleRows(r0, num_rows) * f2.values.middleRows(c0, num_cols).transpose();
      },
      rows, cols);
}

// The integer kernels (descriptor_kernels.h): image 2 packed once per pair, tiles filled by
// the kernel of this CPU's instruction set.
struct IntegerKernel {
  internal::FillDotTile fill = nullptr;
  // x86: columns stored as b - 128 (unsigned by signed bytes); ARM: as b.
  bool offset_columns = false;
};

IntegerKernel IntegerKernelFor(DescriptorKernel kernel) {
  switch (kernel) {
#if defined(__x86_64__)
    case DescriptorKernel::kAvx512Vnni: return {internal::FillDotTileAvx512Vnni, true};
    case DescriptorKernel::kAvx2: return {internal::FillDotTileAvx2, true};
#endif
#if defined(__aarch64__)
    case DescriptorKernel::kNeonDotprod: return {internal::FillDotTileNeonDotprod, false};
    case DescriptorKernel::kNeon: return {internal::FillDotTileNeon, false};
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

template <bool kColumns>
void SearchBest2Integer(const FeatureDescriptors& d1, const FeatureDescriptors& d2,
                        const IntegerKernel& kernel, Best2* rows, Best2* cols) {
  static_assert(kColBlock % internal::kKernelColumnStep == 0);
  static_assert(kDescriptorDim == internal::kKernelDim);
  const PackedColumns packed = PackColumns(d2, kernel.offset_columns);
  SearchBest2<kColumns>(
      static_cast<int>(d1.rows()), RowTerms(d1, kernel.offset_columns), packed.sq_norms,
      [&](int r0, int num_rows, int c0, int num_cols, float* tile) {
        kernel.fill(d1.data() + static_cast<size_t>(r0) * kDescriptorDim, num_rows,
                    packed.bytes.data() +
                        static_cast<size_t>(c0 / internal::kPackedGroup) * internal::kPackedGroupBytes,
                    num_cols, tile);
      },
      rows, cols);
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
  SearchBest2Integer<kColumns>(d1, d2, IntegerKernelFor(kernel), rows, cols);
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
  return IntegerKernelFor(kernel).fill != nullptr && CpuRuns(kernel);
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
