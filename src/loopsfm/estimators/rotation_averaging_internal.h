#pragma once
// Internals shared by rotation_averaging.cc (the L1 and robust stages) and
// rotation_initialization.cc (the largest component and the initial trees). Not part of the
// estimators module's interface.

#include <vector>

#include <Eigen/Geometry>

#include "loopsfm/estimators/rotation_averaging.h"

namespace loopsfm::rotation_averaging_internal {

// The largest connected component of the usable edges, with nodes as dense indices.
struct ComponentProblem {
  // Node index -> image id, increasing.
  std::vector<image_t> ids;
  // Per component edge: its index in the input, its two node indices, its measured
  // cam2_from_cam1 and its measurement weight (scaled so the largest is 1).
  std::vector<int> input_edge;
  std::vector<int> node1;
  std::vector<int> node2;
  std::vector<Eigen::Quaterniond> measured;
  std::vector<double> weight;
  // The node with the largest total edge weight (ties: the smallest id).
  int root = -1;
  int num_ignored = 0;

  int NumNodes() const { return static_cast<int>(ids.size()); }
  int NumEdges() const { return static_cast<int>(input_edge.size()); }
};

// The largest connected component of the usable edges of `edges` (node1 != node2, a finite
// weight > 0); num_ignored counts the others.
ComponentProblem LargestComponent(const std::vector<RelativeRotation>& edges);

// Step 1 of rotation_averaging.h: the rotations of the component's nodes (dense indices)
// that the options' tree propagates from the root.
std::vector<Eigen::Quaterniond> TreeRotations(const ComponentProblem& problem,
                                              const RotationAveragingOptions& options);

}  // namespace loopsfm::rotation_averaging_internal
