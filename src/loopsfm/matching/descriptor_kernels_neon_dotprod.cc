// The NEON dot-product kernel for ARMv8.2-A and later with the dot-product extension
// (compiled with -march=armv8.2-a+dotprod; run only where the CPU reports it: Apple M1 and
// later, Graviton 2 and later, Cortex-A76 and later). See descriptor_kernels.h for the packing.
//
// udot multiplies 16 unsigned bytes by 16 unsigned bytes and adds them in groups of four to 4
// uint32 lanes; the by-element form broadcasts 4 bytes of the row, so one instruction is 4
// bytes of 4 columns. Sums stay below 2^24, exact as floats.

#include <arm_neon.h>

#include "loopsfm/matching/descriptor_kernels.h"
#include "loopsfm/matching/descriptor_search.h"

namespace loopsfm::internal {
namespace {

// a . b for kRows rows and one packed group (16 columns, 4 vectors of 4).
template <int kRows>
inline void DotRowsGroup(const uint8_t* a, const int8_t* group, float* tile, int ld) {
  const uint8_t* b = reinterpret_cast<const uint8_t*>(group);
  uint32x4_t acc[kRows][4];
  for (int r = 0; r < kRows; ++r) {
    for (int k = 0; k < 4; ++k) acc[r][k] = vdupq_n_u32(0);
  }
  for (int q4 = 0; q4 < kKernelDim / 16; ++q4) {
    uint8x16_t va[kRows];
    for (int r = 0; r < kRows; ++r) va[r] = vld1q_u8(a + r * kKernelDim + 16 * q4);
    // Quad q = 4 q4 + lane of the row against block q of the group.
#define LOOPSFM_DOT_LANE(lane)                                              \
  {                                                                         \
    const uint8_t* block = b + (4 * q4 + (lane)) * 64;                      \
    const uint8x16_t b0 = vld1q_u8(block), b1 = vld1q_u8(block + 16);       \
    const uint8x16_t b2 = vld1q_u8(block + 32), b3 = vld1q_u8(block + 48);  \
    for (int r = 0; r < kRows; ++r) {                                       \
      acc[r][0] = vdotq_laneq_u32(acc[r][0], b0, va[r], lane);              \
      acc[r][1] = vdotq_laneq_u32(acc[r][1], b1, va[r], lane);              \
      acc[r][2] = vdotq_laneq_u32(acc[r][2], b2, va[r], lane);              \
      acc[r][3] = vdotq_laneq_u32(acc[r][3], b3, va[r], lane);              \
    }                                                                       \
  }
    LOOPSFM_DOT_LANE(0)
    LOOPSFM_DOT_LANE(1)
    LOOPSFM_DOT_LANE(2)
    LOOPSFM_DOT_LANE(3)
#undef LOOPSFM_DOT_LANE
  }
  for (int r = 0; r < kRows; ++r) {
    for (int k = 0; k < 4; ++k) vst1q_f32(tile + r * ld + 4 * k, vcvtq_f32_u32(acc[r][k]));
  }
}

// The num_rows x num_cols dot products of rows with the packed columns (descriptor_kernels.h).
void FillDotTileNeonDotprod(const uint8_t* rows, int num_rows, const int8_t* packed,
                            int num_cols, float* tile) {
  for (int c = 0; c < num_cols; c += kPackedGroup) {
    const int8_t* group = packed + static_cast<size_t>(c / kPackedGroup) * kPackedGroupBytes;
    int r = 0;
    for (; r + 4 <= num_rows; r += 4) {
      DotRowsGroup<4>(rows + static_cast<size_t>(r) * kKernelDim, group,
                      tile + static_cast<size_t>(r) * num_cols + c, num_cols);
    }
    for (; r < num_rows; ++r) {
      DotRowsGroup<1>(rows + static_cast<size_t>(r) * kKernelDim, group,
                      tile + static_cast<size_t>(r) * num_cols + c, num_cols);
    }
  }
}

}  // namespace

void SearchNeonDotprod(const IntegerSearch& search) { RunIntegerSearch(search, FillDotTileNeonDotprod); }

}  // namespace loopsfm::internal
