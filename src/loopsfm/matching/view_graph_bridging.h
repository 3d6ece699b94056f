#pragma once
// Checks the view graph (frames linked by verified pairs) after pairing and tries to bridge
// where it falls apart or where a frame hangs on few pairs.
//
// Each round proposes, for frames that are not in the largest connected component or that
// have fewer than min_num_partners verified partners:
//  - pairs across the gap in time: where consecutive frames lie in different components,
//    the frames within gap_reach of that boundary are tried with frames on the other side
//    at growing distances (2, 3, 4, 6, 8, 12, 16, 24, ... up to max_gap_frames);
//  - the frame's own best similarity candidates (not the global top-k of the guided rounds,
//    which a strong loop elsewhere in the video can fill), those in other components first,
//    until they fail in max_fruitless_rounds rounds (the candidates are the frame's best few
//    dozen by score, not every frame: memory stays linear in the frames);
//  - the four neighbours in the match matrix of every bridge verified in the round before,
//    so that a bridge found by one pair gets the several pairs a mapper needs to cross it.
// Rounds end when a round verifies nothing new or nothing is left to propose.

#include <vector>

#include "loopsfm/matching/guided_pairing.h"
#include "loopsfm/matching/pair_set.h"

namespace loopsfm {

struct ViewGraphBridgingOptions {
  // Frames with fewer verified partners than this get their own proposals too.
  int min_num_partners = 3;
  // Frames on each side of a gap in time that are tried across it.
  int gap_reach = 8;
  // Largest frame distance tried across a gap.
  int max_gap_frames = 300;
  // Best untried similarity candidates per weak frame and round.
  int num_candidates_per_frame = 5;
  // A frame whose own candidates all failed in this many rounds gets no more of them.
  int max_fruitless_rounds = 2;
  // Safety bound on the number of rounds.
  int max_rounds = 20;
  void Check() const;
};

struct ViewGraphBridgingReport {
  // Connected components and largest component (frames) before and after.
  int num_components_before = 0;
  int largest_component_before = 0;
  int num_components_after = 0;
  int largest_component_after = 0;
  int num_rounds = 0;
  size_t num_tried = 0;
  size_t num_verified = 0;
};

// Frame distances tried across a gap: 2, 3, 4, 6, 8, 12, 16, 24, ... (powers of two and
// 1.5 times powers of two) up to max_distance.
std::vector<int> GapDistances(int max_distance);

// `candidates[i]` are frame i's best-scoring frames (ImageDatabase::Candidates, `best`),
// indices into `ordered_ids` (capture order), or empty when there are none (then only gap and
// growing proposals are made). `tried` and `verified` as for RunGuidedPairing; both are
// updated.
ViewGraphBridgingReport BridgeViewGraph(const std::vector<std::vector<ScoredIndex>>& candidates,
                                        const std::vector<image_t>& ordered_ids,
                                        const ViewGraphBridgingOptions& options,
                                        const VerifyPairsFn& verify, IndexPairSet* tried,
                                        IndexPairSet* verified);

}  // namespace loopsfm
