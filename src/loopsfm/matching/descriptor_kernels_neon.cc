// The NEON dot-product kernel for every ARMv8-A CPU (Cortex-A53, A72: Raspberry Pi 3 and 4).
// See descriptor_kernels.h for the packing; CPUs with the dot-product extension run
// descriptor_kernels_neon_dotprod.cc instead.
//
// umull multiplies 8 unsigned bytes by 8 into uint16 (255^2 fits), uadalp adds neighbouring
// uint16 lanes into uint32 accumulators: a pair of instructions is 8 byte products. Each
// accumulator lane then holds half a column's sum; one pairwise add at the end completes them.

#include <arm_neon.h>

#include <cstring>

#include "loopsfm/matching/descriptor_kernels.h"
#include "loopsfm/matching/descriptor_search.h"

namespace loopsfm::internal {
namespace {

// a . b for kRows rows and one packed group (16 columns).
template <int kRows>
inline void DotRowsGroup(const uint8_t* a, const int8_t* group, float* tile, int ld) {
  const uint8_t* b = reinterpret_cast<const uint8_t*>(group);
  // acc[r][k][h]: columns 4k + 2h and 4k + 2h + 1, two half sums each.
  uint32x4_t acc[kRows][4][2];
  for (int r = 0; r < kRows; ++r) {
    for (int k = 0; k < 4; ++k) acc[r][k][0] = acc[r][k][1] = vdupq_n_u32(0);
  }
  for (int q = 0; q < kKernelDim / 4; ++q) {
    uint8x16_t va[kRows];
    for (int r = 0; r < kRows; ++r) {
      uint32_t quad;
      std::memcpy(&quad, a + r * kKernelDim + 4 * q, sizeof(quad));
      va[r] = vreinterpretq_u8_u32(vdupq_n_u32(quad));
    }
    for (int k = 0; k < 4; ++k) {
      const uint8x16_t bk = vld1q_u8(b + q * 64 + 16 * k);
      for (int r = 0; r < kRows; ++r) {
        acc[r][k][0] = vpadalq_u16(acc[r][k][0], vmull_u8(vget_low_u8(bk), vget_low_u8(va[r])));
        acc[r][k][1] = vpadalq_u16(acc[r][k][1], vmull_high_u8(bk, va[r]));
      }
    }
  }
  for (int r = 0; r < kRows; ++r) {
    for (int k = 0; k < 4; ++k) {
      vst1q_f32(tile + r * ld + 4 * k, vcvtq_f32_u32(vpaddq_u32(acc[r][k][0], acc[r][k][1])));
    }
  }
}

// The num_rows x num_cols dot products of rows with the packed columns (descriptor_kernels.h).
void FillDotTileNeon(const uint8_t* rows, int num_rows, const int8_t* packed, int num_cols,
                     float* tile) {
  for (int c = 0; c < num_cols; c += kPackedGroup) {
    const int8_t* group = packed + static_cast<size_t>(c / kPackedGroup) * kPackedGroupBytes;
    int r = 0;
    for (; r + 2 <= num_rows; r += 2) {
      DotRowsGroup<2>(rows + static_cast<size_t>(r) * kKernelDim, group,
                      tile + static_cast<size_t>(r) * num_cols + c, num_cols);
    }
    for (; r < num_rows; ++r) {
      DotRowsGroup<1>(rows + static_cast<size_t>(r) * kKernelDim, group,
                      tile + static_cast<size_t>(r) * num_cols + c, num_cols);
    }
  }
}

}  // namespace

void SearchNeon(const IntegerSearch& search) { RunIntegerSearch(search, FillDotTileNeon); }

}  // namespace loopsfm::internal
