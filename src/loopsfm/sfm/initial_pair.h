#pragma once
// Choosing and building the two-view start of a model.
//
// Candidates are the verified pairs with a relative pose. Each inlier's triangulation angle
// is the angle between its two viewing rays (cheirality checked by the rays' midpoint
// depths), and a pair's quality is its number of well-conditioned inliers: angle at least
// init_min_tri_angle_deg, in front of both cameras. COLMAP asks the same of an initial pair
// (many inliers, a wide median triangulation angle, not a homography); ranking by the
// count of well-conditioned inliers asks for both at once, so a pair of neighbouring video
// frames (many inliers, tiny angles) or a far pair with few inliers ranks low. Frame order
// only breaks ties.

#include <vector>

#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/sfm/mapper_options.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

class MapperState;

struct InitialPairCandidate {
  const MapperPair* pair = nullptr;
  int num_inliers = 0;
  // Inliers with a triangulation angle of at least init_min_tri_angle_deg, in front of both.
  int num_well_conditioned = 0;
  double median_tri_angle_deg = 0.0;
  // Fraction of the inliers the pair's homography explains.
  double h_ratio = 0.0;
  // Tiers, best first: 0 strict (enough inliers and well-conditioned inliers, not
  // planar), 1 relaxed (half the counts), 2 planar (homography ratio above the bound).
  int tier = 0;
};

// Candidates in the order they are tried: by tier, then most well-conditioned inliers,
// then frame order. Pairs below the relaxed counts are left out.
std::vector<InitialPairCandidate> RankInitialPairs(const MapperInput& input,
                                                   const IncrementalMapperOptions& options);

// Whether a pure rotation of the camera explains a planar (tier 2) candidate's inliers as
// well as its homography does: a camera turning on the spot, which leaves no baseline to
// start from (COLMAP's panoramic pairs), whose two-view model is noise. Such a pair is
// never tried. Asked only of the tier-2 candidates the mapper reaches, not while ranking:
// on a 600-frame video most of the 4,300 candidates are tier 2, and checking them all took
// 7 s before mapping began, while tier 0 or 1 starts nearly every model.
bool TurnsOnTheSpot(const InitialPairCandidate& candidate, const MapperInput& input,
                    const IncrementalMapperOptions& options);

// Builds the two-view model in an empty state: the first frame at the origin, the second at
// the pair's relative pose, triangulation, a global bundle and filtering. Returns whether it
// kept enough points (init_min_num_points, half for tiers above 0) to grow from.
bool InitializeModel(MapperState& state, const InitialPairCandidate& candidate,
                     MapperReport* report);

}  // namespace loopsfm
