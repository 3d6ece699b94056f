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
// A kernel writes the exact integer t(r, c) (as a float: |t| < 2^24) such that
//   |a_r - b_c|^2 = row_term(a_r) + |b_c|^2 - 2 t(r, c).

#include <cstddef>
#include <cstdint>

namespace loopsfm::internal {

constexpr int kKernelDim = 128;                             // bytes per descriptor
constexpr int kPackedGroup = 16;                            // columns per packed group
constexpr int kPackedGroupBytes = kPackedGroup * kKernelDim;  // 2048
// Every kernel fills whole pairs of groups: tiles have a multiple of 32 columns.
constexpr int kKernelColumnStep = 2 * kPackedGroup;

// Writes the num_rows x num_cols dot products (row-major, row stride num_cols) of the rows
// rows[0 .. num_rows) (128 bytes each, contiguous) with the packed columns starting at
// `packed` (num_cols a multiple of kKernelColumnStep).
using FillDotTile = void (*)(const uint8_t* rows, int num_rows, const int8_t* packed,
                             int num_cols, float* tile);

#if defined(__x86_64__)
// AVX-512 F/BW/VNNI: vpdpbusd, 64 unsigned-by-signed byte products per instruction.
void FillDotTileAvx512Vnni(const uint8_t* rows, int num_rows, const int8_t* packed, int num_cols,
                           float* tile);
// AVX2: vpmaddubsw + vpmaddwd, 32 byte products per pair of instructions.
void FillDotTileAvx2(const uint8_t* rows, int num_rows, const int8_t* packed, int num_cols,
                     float* tile);
#endif
#if defined(__aarch64__)
// NEON (every ARMv8-A): umull + uadalp, 16 byte products per pair of instructions.
void FillDotTileNeon(const uint8_t* rows, int num_rows, const int8_t* packed, int num_cols,
                     float* tile);
// NEON with the dot-product extension (ARMv8.2-A+dotprod): udot, 16 byte products.
void FillDotTileNeonDotprod(const uint8_t* rows, int num_rows, const int8_t* packed,
                            int num_cols, float* tile);
#endif

}  // namespace loopsfm::internal
