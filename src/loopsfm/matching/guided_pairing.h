#pragma once
// Vocabulary-tree guided pair selection with region growing.
//
// Each round proposes (a) the highest-scoring loop candidates not tried yet, and
// (b) the horizontal and vertical neighbours in the match matrix, (i±1, j) and (i, j±1), of
// every pair verified in the previous round (video frames that see the same place come in
// runs, so a verified pair's neighbours are likely to verify too). The caller matches and
// verifies the proposals.
//
// The first round proposes k pairs by score; each later round proposes by score as many as
// the previous round's score proposals verified, and none any more once more than
// max_failure_ratio of a round's score proposals failed (the similarity matrix has nothing
// left to offer). The candidates are each frame's best-scoring frames beyond the sequential
// window (ImageDatabase::Candidates), so no n x n matrix is needed. Region growing goes on as
// long as it verifies pairs; the rounds end when nothing is proposed. This rule finds nearly
// every pair exhaustive matching verifies while matching fewer than a fixed k with the stop
// rule on all proposals (docs/benchmarks.md, "Pairing"). Proposals by score skip pairs closer
// in time than min_frame_gap (the sequential part has tried them), and no pair is proposed
// whose two frames already have max_loop_partners loop partners each.

#include <functional>
#include <vector>

#include "loopsfm/matching/pair_set.h"
#include "loopsfm/retrieval/image_database.h"
#include "loopsfm/util/types.h"

namespace loopsfm {

struct GuidedPairingOptions {
  // Highest-scoring untried pairs proposed in the first round (k); 0 means the number of
  // frames. Later rounds propose as many as the previous round's score proposals verified.
  int num_proposals = 0;
  // Score proposals skip pairs at most this many frames apart: the sequential part covers
  // them, and their failures would stop the search for loops (0: none skipped).
  int min_frame_gap = 0;
  // A frame with this many verified partners beyond min_frame_gap is linked to the other
  // passes well enough: a proposal whose two frames both have as many is skipped, so a wide
  // loop band is thinned to a few pairs per frame instead of matched whole (0: no limit,
  // every pair region growing reaches is tried, for recall against exhaustive matching).
  int max_loop_partners = 5;
  // Stop proposing by score when more than this fraction of a round's score proposals fail.
  double max_failure_ratio = 0.7;
  // Safety bound on the number of rounds.
  int max_rounds = 1000;
  void Check() const;
};

struct GuidedPairingRound {
  size_t num_from_scores = 0;
  size_t num_from_growing = 0;
  size_t num_verified = 0;
  // Of num_verified, those proposed by score (the rest came from region growing).
  size_t num_verified_from_scores = 0;
  size_t NumProposed() const { return num_from_scores + num_from_growing; }
};

struct GuidedPairingReport {
  std::vector<GuidedPairingRound> rounds;
  size_t num_tried = 0;
  size_t num_verified = 0;
};

// Matches and verifies the given pairs; returns one flag per pair (true: verified).
using VerifyPairsFn = std::function<std::vector<bool>(const std::vector<ImagePair>&)>;

// `candidates[i]` are frame i's loop candidates: its best-scoring frames more than
// min_frame_gap indices away (ImageDatabase::Candidates, `far`), indices into `image_ids`, which
// are in capture order so that neighbouring indices are neighbouring frames. `tried` holds
// pairs matched before (e.g. sequential neighbours), which are never proposed again; `verified`
// which of them verified. Both are updated with this run's pairs. Verified pairs count as loop
// partners when they are more than min_frame_gap apart and not in `sequential` (optional: the
// pairs the sequential part covered, e.g. its i + 2^k steps and wider first windows, which are
// temporal neighbours, not links to another pass). Pairs verified by an earlier run count, so a
// resumed run does not match the loop bands again (it may try one more round of score
// proposals for frames below the limit).
GuidedPairingReport RunGuidedPairing(const std::vector<std::vector<ScoredIndex>>& candidates,
                                     const std::vector<image_t>& image_ids,
                                     const GuidedPairingOptions& options,
                                     const VerifyPairsFn& verify, IndexPairSet* tried,
                                     IndexPairSet* verified,
                                     const IndexPairSet* sequential = nullptr);

}  // namespace loopsfm
