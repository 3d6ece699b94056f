#pragma once
// The exact best-2 search over tiles of dot products, shared by every matching kernel
// (internal to matching/). It sits in an unnamed namespace on purpose: each kernel file
// compiles its own copy with its own target flags (once the dot products are integer ones, the
// scan is a third of a pair's time, so it must not fall back to SSE2 in a portable build), and
// no copy can stand in for another at link time. Raw pointers and no library calls, for the
// same reason (descriptor_kernels.h).

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

#include "loopsfm/matching/descriptor_kernels.h"

namespace loopsfm::internal {
namespace {

constexpr float kSearchInf = std::numeric_limits<float>::infinity();

// The widest vector of the instruction set this file is compiled for. Vector-extension types
// wider than that are lowered to scalar code for the conditional selects, so the 16 lanes are
// kept as 16 / kVectorLanes vectors of this width.
#if defined(__AVX512F__)
constexpr int kVectorLanes = 16;
#elif defined(__AVX__)
constexpr int kVectorLanes = 8;
#else
constexpr int kVectorLanes = 4;  // SSE2, NEON
#endif
constexpr int kVectorsPerLanes = kLanes / kVectorLanes;
using FloatVector = float __attribute__((vector_size(kVectorLanes * sizeof(float))));
using IntVector = int32_t __attribute__((vector_size(kVectorLanes * sizeof(int32_t))));

// Updates the best-2 of one row (per lane) and of every column with one tile row of dot
// products. Ties keep the lowest index, as a sequential search would. The lanes are GCC / Clang
// vector-extension types the width of the file's registers, so the row's best-2 stays in
// registers and each step is a few compare-and-select instructions.
template <bool kColumns>
inline void ScanTileRow(const float* __restrict dots, int num_cols, float a2,
                        const float* __restrict b2, int32_t row_index, int32_t col_offset,
                        float* __restrict lane_d1, float* __restrict lane_d2,
                        int32_t* __restrict lane_idx, float* __restrict c1,
                        float* __restrict c2, int32_t* __restrict ci) {
  constexpr int V = kVectorLanes;
  FloatVector l1[kVectorsPerLanes], l2[kVectorsPerLanes];
  IntVector li[kVectorsPerLanes], col_index[kVectorsPerLanes];
  for (int v = 0; v < kVectorsPerLanes; ++v) {
    std::memcpy(&l1[v], lane_d1 + v * V, sizeof(FloatVector));
    std::memcpy(&l2[v], lane_d2 + v * V, sizeof(FloatVector));
    std::memcpy(&li[v], lane_idx + v * V, sizeof(IntVector));
    for (int l = 0; l < V; ++l) col_index[v][l] = col_offset + v * V + l;
  }
  for (int c = 0; c < num_cols; c += kLanes) {
    for (int v = 0; v < kVectorsPerLanes; ++v) {
      const int k = c + v * V;
      FloatVector dot, b;
      std::memcpy(&dot, dots + k, sizeof(dot));
      std::memcpy(&b, b2 + k, sizeof(b));
      const FloatVector d = a2 + b - 2.0f * dot;
      const IntVector lt = d < l1[v];
      l2[v] = lt ? l1[v] : (d < l2[v] ? d : l2[v]);
      li[v] = lt ? col_index[v] : li[v];
      l1[v] = lt ? d : l1[v];
      col_index[v] += kLanes;
      if constexpr (kColumns) {
        FloatVector cb1, cb2;
        IntVector cbi;
        std::memcpy(&cb1, c1 + k, sizeof(cb1));
        std::memcpy(&cb2, c2 + k, sizeof(cb2));
        std::memcpy(&cbi, ci + k, sizeof(cbi));
        const IntVector clt = d < cb1;
        cb2 = clt ? cb1 : (d < cb2 ? d : cb2);
        cbi = clt ? IntVector{} + row_index : cbi;
        cb1 = clt ? d : cb1;
        std::memcpy(c1 + k, &cb1, sizeof(cb1));
        std::memcpy(c2 + k, &cb2, sizeof(cb2));
        std::memcpy(ci + k, &cbi, sizeof(cbi));
      }
    }
  }
  for (int v = 0; v < kVectorsPerLanes; ++v) {
    std::memcpy(lane_d1 + v * V, &l1[v], sizeof(FloatVector));
    std::memcpy(lane_d2 + v * V, &l2[v], sizeof(FloatVector));
    std::memcpy(lane_idx + v * V, &li[v], sizeof(IntVector));
  }
}

// Exact best-2 search in both directions (columns only when kColumns), tile by tile:
// fill_tile(r0, num_rows, c0, num_cols, tile) writes the num_rows x num_cols dot products
// (row-major) such that row_norms[r] + col_norms[c] - 2 tile(r, c) is the squared distance.
// Columns are padded to a multiple of kLanes with infinite norms. Writes rows' n1 entries and,
// with kColumns, the columns' n2_padded ones.
template <bool kColumns, typename FillTile>
void SearchBest2(int n1, const float* row_norms, int n2_padded, const float* col_norms,
                 FillTile&& fill_tile, const SearchScratch& scratch, const Best2Arrays& rows,
                 const Best2Arrays& cols) {
  if constexpr (kColumns) {
    for (int j = 0; j < n2_padded; ++j) {
      cols.best[j] = cols.second[j] = kSearchInf;
      cols.index[j] = -1;
    }
  }
  // Every tile entry is written before it is read: no need to zero 1 MB per pair.
  float* tile = scratch.tile;
  float* lane_d1 = scratch.lane_best;
  float* lane_d2 = scratch.lane_second;
  int32_t* lane_idx = scratch.lane_index;

  for (int r0 = 0; r0 < n1; r0 += kRowBlock) {
    const int num_rows = n1 - r0 < kRowBlock ? n1 - r0 : kRowBlock;
    for (int k = 0; k < kRowBlock * kLanes; ++k) {
      lane_d1[k] = lane_d2[k] = kSearchInf;
      lane_idx[k] = -1;
    }
    for (int c0 = 0; c0 < n2_padded; c0 += kColBlock) {
      const int num_cols = n2_padded - c0 < kColBlock ? n2_padded - c0 : kColBlock;
      fill_tile(r0, num_rows, c0, num_cols, tile);
      for (int r = 0; r < num_rows; ++r) {
        ScanTileRow<kColumns>(tile + static_cast<size_t>(r) * num_cols, num_cols,
                              row_norms[r0 + r], col_norms + c0, r0 + r, c0,
                              lane_d1 + r * kLanes, lane_d2 + r * kLanes, lane_idx + r * kLanes,
                              kColumns ? cols.best + c0 : nullptr,
                              kColumns ? cols.second + c0 : nullptr,
                              kColumns ? cols.index + c0 : nullptr);
      }
    }
    // Merge the lanes of each row into its best-2.
    for (int r = 0; r < num_rows; ++r) {
      float b1 = kSearchInf, b2 = kSearchInf;
      int32_t bi = -1;
      for (int l = 0; l < kLanes; ++l) {
        const float d = lane_d1[r * kLanes + l];
        const int32_t i = lane_idx[r * kLanes + l];
        if (i >= 0 && (d < b1 || (d == b1 && i < bi))) {
          b2 = b1 < b2 ? b1 : b2;
          b1 = d;
          bi = i;
        } else {
          b2 = d < b2 ? d : b2;
        }
        b2 = lane_d2[r * kLanes + l] < b2 ? lane_d2[r * kLanes + l] : b2;
      }
      rows.best[r0 + r] = b1;
      rows.second[r0 + r] = b2;
      rows.index[r0 + r] = bi;
    }
  }
}

// The search of one pair with an integer kernel's fill_tile(rows, num_rows, packed, num_cols,
// tile) (descriptor_kernels.h).
template <typename FillDots>
void RunIntegerSearch(const IntegerSearch& s, FillDots fill_dots) {
  auto fill_tile = [&](int r0, int num_rows, int c0, int num_cols, float* tile) {
    fill_dots(s.rows + static_cast<size_t>(r0) * kKernelDim, num_rows,
              s.packed + static_cast<size_t>(c0 / kPackedGroup) * kPackedGroupBytes, num_cols,
              tile);
  };
  if (s.col_best.best != nullptr) {
    SearchBest2<true>(s.num_rows, s.row_terms, s.num_cols, s.col_norms, fill_tile, s.scratch,
                      s.row_best, s.col_best);
  } else {
    SearchBest2<false>(s.num_rows, s.row_terms, s.num_cols, s.col_norms, fill_tile, s.scratch,
                       s.row_best, s.col_best);
  }
}

}  // namespace
}  // namespace loopsfm::internal
