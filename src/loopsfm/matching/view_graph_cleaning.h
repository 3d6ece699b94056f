#pragma once
// Cleans the view graph (images linked by verified pairs with relative rotations) before
// rotation averaging: drops edges whose rotation disagrees with the rest of the graph around
// triangles, then keeps the largest connected component.
//
// A triangle (i, j, k) of edges passes when its loop rotation R_ki R_jk R_ij, with R_ab the
// measured cam_b_from_cam_a, is within max_loop_error_deg of the identity. An outlier edge
// fails every triangle it lies in; a good edge fails only the triangles it shares with an
// outlier. So:
//  1. every edge that fails all its triangles is dropped;
//  2. then edges are dropped one at a time, worst first (the smallest fraction of passing
//     triangles, then the most failing ones), while the worst passes fewer than
//     min_pass_fraction of its remaining triangles. A drop removes the edge's triangles, so a
//     good edge that shared failing triangles with outliers is judged on the rest.
// A good edge is dropped only when outliers lie in all or most of its triangles. Edges in
// no triangle are kept: nothing speaks against them. With weigh_triangles, steps 1 and 2
// weigh each triangle by the weaker of its other two edges (the pairs' inliers) instead of
// counting it: weak pairs that are off by the same rotation pass their triangles among
// themselves and can outnumber a good pair of many inliers, not outweigh it.
//
//   ViewGraphCleaningResult cleaned = CleanViewGraph(edges, options);
//   for (int e : cleaned.kept_edges) use(edges[e]);

#include <vector>

#include "loopsfm/scene/relative_rotation.h"

namespace loopsfm {

struct ViewGraphCleaningOptions {
  // A triangle passes when the angle of its loop rotation is at most this (degrees).
  double max_loop_error_deg = 5.0;
  // After step 1, an edge is dropped while fewer than this fraction of its remaining
  // triangles pass (step 2 above); in (0, 1].
  double min_pass_fraction = 0.5;
  // Weigh what a triangle says about one of its edges by the weaker of its other two edges'
  // weights (see above) instead of counting it.
  bool weigh_triangles = false;
  // Keep only the largest connected component of the edges that survive.
  bool keep_largest_component = true;
  void Check() const;  // throws InvalidArgument
};

struct ViewGraphCleaningReport {
  int num_input_edges = 0;
  // Input edges not used: node1 == node2, a pair that occurred before (in either direction),
  // or a weight that is not finite and > 0.
  int num_ignored_edges = 0;
  int num_triangles = 0;
  int num_failed_triangles = 0;
  // Kept edges that were in no triangle to begin with (their rotations are unchecked).
  int num_edges_in_no_triangle = 0;
  int num_dropped_by_triangles = 0;
  int num_dropped_outside_component = 0;
  // Nodes and edges kept.
  int num_nodes = 0;
  int num_edges = 0;
  double time_s = 0.0;
};

struct ViewGraphCleaningResult {
  // Indices into the input edges of the edges kept, increasing.
  std::vector<int> kept_edges;
  ViewGraphCleaningReport report;
};

ViewGraphCleaningResult CleanViewGraph(const std::vector<RelativeRotation>& edges,
                                       const ViewGraphCleaningOptions& options = {});

// Angle of the loop rotation R_ki R_jk R_ij of three edges that form a triangle, each given
// in either direction (degrees).
double LoopErrorDegrees(const RelativeRotation& a, const RelativeRotation& b,
                        const RelativeRotation& c);

}  // namespace loopsfm
