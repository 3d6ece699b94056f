#pragma once
// Vocabulary-tree guided pair selection with region growing.
//
// Each round proposes (a) the `num_proposals` highest-scoring pairs of the similarity matrix
// not tried yet, and (b) the horizontal and vertical neighbours in the match matrix, (i±1, j)
// and (i, j±1), of every pair verified in the previous round (video frames that see the
// same place come in runs, so a verified pair's neighbours are likely to verify too). The
// caller matches and verifies the proposals; the rounds stop when more than
// max_failure_ratio of a round's proposals fail verification (most proposals fail), or when
// nothing is left to propose. The threshold is a fraction of all of the round's proposals,
// not of k alone, so a round whose region growing still succeeds goes on even when its
// score-based proposals mostly fail.

#include <functional>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/util/types.h"

namespace loopsfm {

struct GuidedPairingOptions {
  // Highest-scoring untried pairs proposed per round (k); 0 means the number of frames.
  int num_proposals = 0;
  // Stop when more than this fraction of a round's proposals fail verification.
  double max_failure_ratio = 0.7;
  // Safety bound on the number of rounds.
  int max_rounds = 1000;
  void Check() const;
};

struct GuidedPairingRound {
  size_t num_from_scores = 0;
  size_t num_from_growing = 0;
  size_t num_verified = 0;
  size_t NumProposed() const { return num_from_scores + num_from_growing; }
};

struct GuidedPairingReport {
  std::vector<GuidedPairingRound> rounds;
  size_t num_tried = 0;
  size_t num_verified = 0;
};

// Matches and verifies the given pairs; returns one flag per pair (true: verified).
using VerifyPairsFn = std::function<std::vector<bool>(const std::vector<ImagePair>&)>;

// `scores` is the n x n similarity of `image_ids` (row/column i is image_ids[i], which
// are in capture order so that neighbouring indices are neighbouring frames). `tried`
// marks pairs matched before (e.g. sequential neighbours), which are never proposed again:
// n x n, symmetric; `verified` likewise marks which of them verified. Both are updated with
// this run's pairs.
GuidedPairingReport RunGuidedPairing(const Eigen::MatrixXf& scores,
                                     const std::vector<image_t>& image_ids,
                                     const GuidedPairingOptions& options,
                                     const VerifyPairsFn& verify,
                                     Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic>* tried,
                                     Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic>* verified);

}  // namespace loopsfm
