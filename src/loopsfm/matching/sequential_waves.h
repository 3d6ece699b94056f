#pragma once
// Sequential pairing that adapts to the video: each frame is tried with the frames after it
// in waves of growing frame distance, and the results of one wave decide the next.
//
// - Linear window: frame i with i+1, i+2, ... up to the overlap. The window goes on past a
//   failed pair (a blurred frame, a frame whose features are all on a passing object) and
//   stops only after several consecutive failures, never before a minimum window.
// - Quadratic steps: then i + 2^k beyond the window (COLMAP's quadratic overlap), which
//   bridges abrupt turns and short bad stretches (a 90 degree turn between two frames leaves
//   frames 14-18 apart that still share the corner), until a few consecutive steps fail.
//
// The caller matches and verifies the pairs of each wave.

#include <vector>

#include "loopsfm/matching/guided_pairing.h"
#include "loopsfm/matching/pair_set.h"
#include "loopsfm/matching/pair_selection.h"

namespace loopsfm {

struct SequentialWavesOptions {
  // A frame's linear window covers at least this many following frames (capped by the window).
  int min_window = 5;
  // ... and stops after this many consecutive failed pairs beyond that.
  int max_consecutive_failures = 3;
  // Quadratic steps i + 2^k beyond the window, up to this frame distance (0: none).
  int max_quadratic_step = 512;
  // A frame's quadratic steps stop after this many consecutive failures.
  int max_quadratic_failures = 2;
  void Check() const;
};

struct SequentialWavesReport {
  size_t num_tried = 0;
  size_t num_verified = 0;
  // Of those, from the quadratic steps.
  size_t num_quadratic_tried = 0;
  size_t num_quadratic_verified = 0;
};

// `tried` and `verified` are sets of index pairs over `ordered_ids` (capture order); pairs
// already tried are not proposed again (whether they are in `verified` stands for the result)
// and both sets are updated with this run's pairs. `covered` (optional) is set to every pair
// the waves reached, tried now or before: the same set when a run is resumed.
// `window` gives the window sizes (overlap, and initial_overlap for the first
// num_initial_frames frames); its quadratic_overlap flag is not used (the waves have their own).
SequentialWavesReport RunSequentialWaves(const std::vector<image_t>& ordered_ids,
                                         const SequentialPairingOptions& window,
                                         const SequentialWavesOptions& options,
                                         const VerifyPairsFn& verify, IndexPairSet* tried,
                                         IndexPairSet* verified,
                                         IndexPairSet* covered = nullptr);

}  // namespace loopsfm
