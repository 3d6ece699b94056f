// The AVX-512 VNNI dot-product kernel (compiled with -mavx512f -mavx512bw -mavx512vnni; run
// only where the CPU has them). See descriptor_kernels.h for the packing.
//
// vpdpbusd multiplies 64 unsigned bytes of a by 64 signed bytes of b - 128 and adds them in
// groups of four to 16 int32 lanes: one instruction per 4 bytes of 16 columns. The int32 sums
// are exact (|a.(b - 128)| < 2^23), and so are their float copies.

#include <immintrin.h>

#include <cstring>

#include "loopsfm/matching/descriptor_kernels.h"
#include "loopsfm/matching/descriptor_search.h"

namespace loopsfm::internal {
namespace {

// Dot products of kRows rows of a with two packed groups (32 columns), as floats into tile
// rows of stride ld.
template <int kRows>
inline void DotRowsTwoGroups(const uint8_t* a, const int8_t* groups, float* tile, int ld) {
  __m512i acc[kRows][2];
  for (int r = 0; r < kRows; ++r) acc[r][0] = acc[r][1] = _mm512_setzero_si512();
  for (int q = 0; q < kKernelDim / 4; ++q) {
    const __m512i b0 = _mm512_loadu_si512(groups + q * 64);
    const __m512i b1 = _mm512_loadu_si512(groups + kPackedGroupBytes + q * 64);
    for (int r = 0; r < kRows; ++r) {
      int32_t quad;
      std::memcpy(&quad, a + r * kKernelDim + 4 * q, sizeof(quad));
      const __m512i va = _mm512_set1_epi32(quad);
      acc[r][0] = _mm512_dpbusd_epi32(acc[r][0], va, b0);
      acc[r][1] = _mm512_dpbusd_epi32(acc[r][1], va, b1);
    }
  }
  for (int r = 0; r < kRows; ++r) {
    _mm512_storeu_ps(tile + r * ld, _mm512_cvtepi32_ps(acc[r][0]));
    _mm512_storeu_ps(tile + r * ld + kPackedGroup, _mm512_cvtepi32_ps(acc[r][1]));
  }
}

// The num_rows x num_cols dot products of rows with the packed columns (descriptor_kernels.h).
void FillDotTileAvx512Vnni(const uint8_t* rows, int num_rows, const int8_t* packed, int num_cols,
                           float* tile) {
  for (int c = 0; c < num_cols; c += kKernelColumnStep) {
    const int8_t* groups = packed + static_cast<size_t>(c / kPackedGroup) * kPackedGroupBytes;
    int r = 0;
    for (; r + 4 <= num_rows; r += 4) {
      DotRowsTwoGroups<4>(rows + static_cast<size_t>(r) * kKernelDim, groups,
                          tile + static_cast<size_t>(r) * num_cols + c, num_cols);
    }
    for (; r < num_rows; ++r) {
      DotRowsTwoGroups<1>(rows + static_cast<size_t>(r) * kKernelDim, groups,
                          tile + static_cast<size_t>(r) * num_cols + c, num_cols);
    }
  }
}

}  // namespace

void SearchAvx512Vnni(const IntegerSearch& search) { RunIntegerSearch(search, FillDotTileAvx512Vnni); }

}  // namespace loopsfm::internal
