#pragma once
// Least-squares alignment of two point sets (Umeyama 1991, "Least-squares estimation of
// transformation parameters between two point patterns"): the similarity (or rigid)
// transform dst_from_src minimising sum_i |dst_i - (s R src_i + t)|^2.
// Used for trajectory evaluation (ATE after Sim3 alignment) and loop closing.

#include <optional>
#include <span>

#include <Eigen/Core>

#include "loopsfm/geometry/rigid3.h"

namespace loopsfm {

// Similarity transform mapping src to dst: dst_i ~ scale * (rotation * src_i) + translation.
// nullopt for degenerate input: sizes differ, fewer than 3 points, src or dst collinear
// (or coincident), rotation not determined, or non-finite values.
std::optional<Sim3d> EstimateSim3(std::span<const Eigen::Vector3d> src,
                                  std::span<const Eigen::Vector3d> dst);

// Same without scale (scale fixed to 1): dst_i ~ rotation * src_i + translation.
std::optional<Rigid3d> EstimateRigid3(std::span<const Eigen::Vector3d> src,
                                      std::span<const Eigen::Vector3d> dst);

}  // namespace loopsfm
