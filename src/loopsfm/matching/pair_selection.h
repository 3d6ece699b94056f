#pragma once
// Which image pairs to match: sequential (video order) and exhaustive pairing.

#include <vector>

#include "loopsfm/util/types.h"

namespace loopsfm {

struct SequentialPairingOptions {
  // Number of following frames each frame is matched against.
  int overlap = 10;
  // Larger overlap for the first frames, so the initial pair can have a wide baseline.
  int initial_overlap = 30;
  // Number of leading frames that are matched with initial_overlap following frames (0 = none).
  int num_initial_frames = 10;
  // Also match frame i with i + 2^k for 2^k beyond the overlap, k < overlap (COLMAP's
  // quadratic overlap), which links distant frames of slow sequences at little cost.
  bool quadratic_overlap = false;

  // Throws loopsfm::InvalidArgument with a readable message.
  void Check() const;
};

// Pairs of frames close in capture order. Frame i (position in ordered_image_ids) is paired
// with the frames i+1 .. i+overlap; the first num_initial_frames frames with
// i+1 .. i+initial_overlap instead. Pairs come sorted by (position of the first frame,
// position of the second) and contain no duplicates; ImagePair stores the smaller id first.
// Throws InvalidArgument when an id appears twice or is kInvalidImageId.
std::vector<ImagePair> SequentialPairs(const std::vector<image_t>& ordered_image_ids,
                                       const SequentialPairingOptions& options);

// All n (n - 1) / 2 pairs, in the order (0,1), (0,2), ..., (1,2), ... of the input.
// Throws InvalidArgument when an id appears twice or is kInvalidImageId.
std::vector<ImagePair> ExhaustivePairs(const std::vector<image_t>& image_ids);

}  // namespace loopsfm
