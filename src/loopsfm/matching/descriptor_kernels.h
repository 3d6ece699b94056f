#pragma once
// The integer dot-product kernels of descriptor matching (internal to matching/).
//
// One file per instruction set (descriptor_kernels_avx512.cc, _avx2.cc, _neon.cc,
// _neon_dotprod.cc), each compiled with its own target flags (matching/CMakeLists.txt) and
// chosen at run time by descriptor_matcher.cc, so one build runs the fastest kernel on every
// CPU. Those files see raw pointers only: were they to instantiate an inline function that other
// files share (std::vector, Eigen), the linker could keep their AVX-512 copy for everyone.
//
// Image 2's descriptors are packed in groups of kPackedGroup: within a group, block q (64
// bytes) holds bytes 4q..4q+3 of each of the 16 descriptors. The x86 kernels multiply unsigned
// by signed bytes, so their packing stores b - 128 (the top bit flipped) and the row term
// becomes |a|^2 - 256 sum(a); the ARM kernels multiply unsigned by unsigned and take b as is.
// A kernel's dot products are the exact integers t(r, c) (as floats: |t| < 2^24) such that
//   |a_r - b_c|^2 = row_term(a_r) + |b_c|^2 - 2 t(r, c),
// and each file runs its own copy of the best-2 search over them (descriptor_search.h).

#include <cstddef>
#include <cstdint>

namespace loopsfm::internal {

constexpr int kKernelDim = 128;                             // bytes per descriptor
constexpr int kPackedGroup = 16;                            // columns per packed group
constexpr int kPackedGroupBytes = kPackedGroup * kKernelDim;  // 2048
// Every kernel fills whole pairs of groups: tiles have a multiple of 32 columns.
constexpr int kKernelColumnStep = 2 * kPackedGroup;

// The running best-2 of a row is kept per lane (column index modulo kLanes), so the scan over
// a row of dot products vectorises; the lanes are merged once per row.
constexpr int kLanes = 16;
// Tiles of kRowBlock x kColBlock dot products (1 MB) stay in L2 while they are scanned.
constexpr int kRowBlock = 256;
constexpr int kColBlock = 1024;
static_assert(kColBlock % kLanes == 0 && kColBlock % kKernelColumnStep == 0);

// Best and second-best squared distance and the best index, per row or column (caller's arrays).
struct Best2Arrays {
  float* best = nullptr;
  float* second = nullptr;
  int32_t* index = nullptr;
};

// Scratch memory of one search: a tile and the per-lane best-2 of its rows.
struct SearchScratch {
  float* tile = nullptr;         // kRowBlock * kColBlock
  float* lane_best = nullptr;    // kRowBlock * kLanes each
  float* lane_second = nullptr;
  int32_t* lane_index = nullptr;
};

// One pair's exact best-2 search with an integer kernel (descriptor_search.h).
struct IntegerSearch {
  const uint8_t* rows = nullptr;  // image 1: num_rows x 128 bytes
  int num_rows = 0;
  const float* row_terms = nullptr;  // |a|^2, minus 256 sum(a) with offset columns
  const int8_t* packed = nullptr;    // image 2, packed
  int num_cols = 0;                  // padded to a multiple of kKernelColumnStep
  const float* col_norms = nullptr;  // |b|^2, infinite for padding
  SearchScratch scratch;
  Best2Arrays row_best;  // num_rows entries
  Best2Arrays col_best;  // num_cols entries; all null: rows only
};
using IntegerSearchFn = void (*)(const IntegerSearch& search);

#if defined(__x86_64__)
// AVX-512 F/BW/VNNI: vpdpbusd, 64 unsigned-by-signed byte products per instruction.
void SearchAvx512Vnni(const IntegerSearch& search);
// AVX2: vpmaddubsw + vpmaddwd, 32 byte products per pair of instructions.
void SearchAvx2(const IntegerSearch& search);
#endif
#if defined(__aarch64__)
// NEON (every ARMv8-A): umull + uadalp, 8 byte products per pair of instructions.
void SearchNeon(const IntegerSearch& search);
// NEON with the dot-product extension (ARMv8.2-A+dotprod): udot, 16 byte products.
void SearchNeonDotprod(const IntegerSearch& search);
#endif

}  // namespace loopsfm::internal
