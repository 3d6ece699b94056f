// The AVX2 dot-product kernel (compiled with -mavx2 -mno-avx512f, so what is measured on an
// AVX-512 CPU is what an AVX2-only CPU runs). See descriptor_kernels.h for the packing.
//
// AVX2 has no vpdpbusd. vpmaddubsw multiplies 32 unsigned bytes of a by 32 signed bytes of
// b - 128 and adds neighbouring products into 16 int16 lanes, with saturation; vpmaddwd by ones
// then adds neighbouring int16 lanes into 8 int32 ones, so the pair does what one vpdpbusd does
// on half the width. The int16 sums are exact when a <= 127: |2 * 127 * 128| < 2^15.
// SIFT bytes are 128 or more in a few descriptors only, and then in one or two of the 128 bytes,
// so a row is split as a = min(a, 127) + r: the clamped row takes the fast path with the others,
// and the residual r (at most 128, whose int16 sums lie in [-2^15, 2 * 128 * 127], still exact)
// is added afterwards for the few 4-byte quads where it is not zero.

#include <immintrin.h>

#include <cstring>

#include "loopsfm/matching/descriptor_kernels.h"
#include "loopsfm/matching/descriptor_search.h"

namespace loopsfm::internal {
namespace {

// 32 int32 sums of a quad of bytes times the 16 columns of block q of a group (two halves).
inline void DotQuad(__m256i va, const int8_t* block, __m256i ones, __m256i* lo, __m256i* hi) {
  const __m256i b0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(block));
  const __m256i b1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(block + 32));
  *lo = _mm256_add_epi32(*lo, _mm256_madd_epi16(_mm256_maddubs_epi16(va, b0), ones));
  *hi = _mm256_add_epi32(*hi, _mm256_madd_epi16(_mm256_maddubs_epi16(va, b1), ones));
}

// a . (b - 128) for kRows rows (every byte at most 127) and one group of 16 columns.
template <int kRows>
inline void DotRowsGroup(const uint8_t* a, const int8_t* group, float* tile, int ld) {
  const __m256i ones = _mm256_set1_epi16(1);
  __m256i acc[kRows][2];
  for (int r = 0; r < kRows; ++r) acc[r][0] = acc[r][1] = _mm256_setzero_si256();
  for (int q = 0; q < kKernelDim / 4; ++q) {
    for (int r = 0; r < kRows; ++r) {
      // A broadcast straight from memory: a load, no shuffle.
      const __m256i va = _mm256_castps_si256(
          _mm256_broadcast_ss(reinterpret_cast<const float*>(a + r * kKernelDim + 4 * q)));
      DotQuad(va, group + q * 64, ones, &acc[r][0], &acc[r][1]);
    }
  }
  for (int r = 0; r < kRows; ++r) {
    _mm256_storeu_ps(tile + r * ld, _mm256_cvtepi32_ps(acc[r][0]));
    _mm256_storeu_ps(tile + r * ld + 8, _mm256_cvtepi32_ps(acc[r][1]));
  }
}

// The part of a row above 127 in one of its quads.
struct Residual {
  int row;      // within the chunk
  int q;        // quad index
  uint32_t quad;  // max(a - 127, 0), byte-wise
};

// The num_rows x num_cols dot products of rows with the packed columns (descriptor_kernels.h).
void FillDotTileAvx2(const uint8_t* rows, int num_rows, const int8_t* packed, int num_cols,
                     float* tile) {
  constexpr int kRows = 4;
  constexpr int kChunk = 64;  // rows clamped at a time (8 KB on the stack)
  alignas(32) uint8_t clamped[kChunk * kKernelDim];
  Residual residuals[kChunk * kKernelDim / 4];
  const __m256i max_byte = _mm256_set1_epi8(127);
  const __m256i zero = _mm256_setzero_si256();
  const __m256i ones = _mm256_set1_epi16(1);
  for (int r0 = 0; r0 < num_rows; r0 += kChunk) {
    const int n = num_rows - r0 < kChunk ? num_rows - r0 : kChunk;
    const uint8_t* a = rows + static_cast<size_t>(r0) * kKernelDim;
    int num_residuals = 0;
    for (int i = 0; i < n * kKernelDim; i += 32) {
      const __m256i v = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a + i));
      _mm256_store_si256(reinterpret_cast<__m256i*>(clamped + i), _mm256_min_epu8(v, max_byte));
      const __m256i over = _mm256_subs_epu8(v, max_byte);
      // One bit per byte that is not zero; four per quad.
      const uint32_t nonzero = ~static_cast<uint32_t>(_mm256_movemask_epi8(_mm256_cmpeq_epi8(over, zero)));
      if (nonzero == 0) continue;
      alignas(32) uint32_t quads[8];
      _mm256_store_si256(reinterpret_cast<__m256i*>(quads), over);
      for (int k = 0; k < 8; ++k) {
        if ((nonzero >> (4 * k)) & 0xfu) {
          const int byte = i + 4 * k;
          residuals[num_residuals++] = {byte / kKernelDim, (byte % kKernelDim) / 4, quads[k]};
        }
      }
    }
    for (int c = 0; c < num_cols; c += kPackedGroup) {
      const int8_t* group = packed + static_cast<size_t>(c / kPackedGroup) * kPackedGroupBytes;
      float* out = tile + static_cast<size_t>(r0) * num_cols + c;
      int r = 0;
      for (; r + kRows <= n; r += kRows) {
        DotRowsGroup<kRows>(clamped + r * kKernelDim, group, out + static_cast<size_t>(r) * num_cols,
                            num_cols);
      }
      for (; r < n; ++r) {
        DotRowsGroup<1>(clamped + r * kKernelDim, group, out + static_cast<size_t>(r) * num_cols,
                        num_cols);
      }
      // The residuals: integer sums below 2^24 in magnitude, so the float additions are exact.
      for (int k = 0; k < num_residuals; ++k) {
        const Residual& res = residuals[k];
        __m256i lo = zero, hi = zero;
        DotQuad(_mm256_set1_epi32(static_cast<int32_t>(res.quad)), group + res.q * 64, ones, &lo,
                &hi);
        float* row_out = out + static_cast<size_t>(res.row) * num_cols;
        _mm256_storeu_ps(row_out, _mm256_add_ps(_mm256_loadu_ps(row_out), _mm256_cvtepi32_ps(lo)));
        _mm256_storeu_ps(row_out + 8,
                         _mm256_add_ps(_mm256_loadu_ps(row_out + 8), _mm256_cvtepi32_ps(hi)));
      }
    }
  }
}

}  // namespace

void SearchAvx2(const IntegerSearch& search) { RunIntegerSearch(search, FillDotTileAvx2); }

}  // namespace loopsfm::internal
