#pragma once
// Nearest-neighbour matching of SIFT descriptors with Lowe's ratio test and a cross check.
//
// Distances are exact. The dot products of the uint8 descriptors come from a blocked matrix
// product: an integer kernel of our own for the CPU's instruction set (AVX-512 VNNI, AVX2,
// NEON with or without the dot-product extension; descriptor_kernels.h), chosen at run time,
// or Eigen's float GEMM on float copies, where every partial sum is an integer below 2^24. The
// squared distance |a|^2 + |b|^2 - 2 a.b is exact either way, so every kernel gives identical
// matches; the best and second-best neighbours are found in the same pass over each block, in
// both directions.
// Memory stays bounded (a few MB besides the float copies of the descriptors) whatever the
// descriptor counts.
//
// MatchDescriptors is single-threaded and reentrant: match different pairs from different
// threads (e.g. inside tbb::parallel_for). Eigen runs single-threaded unless the build adds
// OpenMP, which loopsfm does not, so there is no nested parallelism.

#include <string>
#include <vector>

#include "loopsfm/scene/features.h"

namespace loopsfm {

// Which dot-product kernel matches descriptors. All give identical matches; they differ in
// speed and in the CPUs that run them.
enum class DescriptorKernel {
  kAuto,         // the fastest this CPU runs, in the order below
  kAvx512Vnni,   // x86-64 with AVX-512 F, BW and VNNI
  kAvx2,         // x86-64 with AVX2 (x86-64-v3)
  kNeonDotprod,  // ARMv8.2-A and later with the dot-product extension
  kNeon,         // every ARMv8-A CPU
  kFloat,        // Eigen's float GEMM, everywhere
};
std::string DescriptorKernelName(DescriptorKernel kernel);  // "auto", "avx2", ...
// Throws loopsfm::InvalidArgument naming the choices.
DescriptorKernel ParseDescriptorKernel(const std::string& name);
// Whether this build and CPU run the kernel (kAuto and kFloat always).
bool DescriptorKernelAvailable(DescriptorKernel kernel);
// The kernels this build and CPU run, fastest first (kFloat last; never kAuto).
std::vector<DescriptorKernel> AvailableDescriptorKernels();
// What kAuto runs.
DescriptorKernel FastestDescriptorKernel();

struct DescriptorMatchingOptions {
  // Lowe's ratio test: keep the nearest neighbour only when its L2 distance is below
  // max_ratio times the distance of the second-nearest one (in (0, 1]).
  double max_ratio = 0.8;
  // Largest L2 distance between the unit-length descriptors (uint8 value / 512), in (0, 2];
  // 2 or more disables the test. COLMAP's 0.7 (an angle there) is close to 0.7 here.
  double max_distance = 0.7;
  // Keep i -> j only when j's nearest neighbour in the first image is i, and j -> i passes
  // the ratio and distance tests too (COLMAP's cross check).
  bool cross_check = true;
  // The dot-product kernel; a named one must run on this CPU (tests, benchmarks, `loopsfm match
  // --match-kernel`).
  DescriptorKernel kernel = DescriptorKernel::kAuto;

  // Throws loopsfm::InvalidArgument with a readable message.
  void Check() const;
};

// Matches of descriptors1 (image 1) to descriptors2 (image 2), sorted by point2D_idx1.
// Without cross_check, several features of image 1 may match one feature of image 2.
// With a single candidate in the other image, the ratio test passes trivially.
FeatureMatches MatchDescriptors(const FeatureDescriptors& descriptors1,
                                const FeatureDescriptors& descriptors2,
                                const DescriptorMatchingOptions& options);

// Best and second-best neighbour of every row of descriptors1 among descriptors2, with squared
// L2 distances in uint8 descriptor units (exact); what MatchDescriptors tests. Exposed for
// tests, benchmarks and diagnostics. second_distance is +inf when there is no second one.
struct NearestNeighbors {
  std::vector<int> index;                  // best neighbour, -1 when descriptors2 is empty
  std::vector<float> best_distance;        // squared L2 to the best neighbour
  std::vector<float> second_distance;      // squared L2 to the second-best neighbour
};
NearestNeighbors FindNearestNeighbors(const FeatureDescriptors& descriptors1,
                                      const FeatureDescriptors& descriptors2,
                                      DescriptorKernel kernel = DescriptorKernel::kAuto);

}  // namespace loopsfm
