#pragma once
// What the mappers read: plain values, loaded from the database by the pipeline, so the
// mappers never touch storage. Tracks are the ones built from matching (before any mapper
// prunes them); the mapper keeps them unchanged for loop closing.

#include <climits>
#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/scene/camera.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/scene/track.h"
#include "loopsfm/scene/two_view_geometry.h"

namespace loopsfm {

struct MapperFrame {
  image_t image_id = kInvalidImageId;
  camera_t camera_id = kInvalidCameraId;
  std::string name;
  // Keypoint positions, COLMAP pixel convention.
  std::vector<Eigen::Vector2d> points2D;
};

struct MapperPair {
  ImagePair pair;
  // Verified geometry; inlier matches index pair.image_id1's and pair.image_id2's points.
  TwoViewGeometry geometry;
};

struct MapperInput {
  std::vector<Camera> cameras;
  // In capture order.
  std::vector<MapperFrame> frames;
  // Verified pairs only.
  std::vector<MapperPair> pairs;
  // Conflict-free tracks over the verified matches.
  std::vector<Track> tracks;
};

// A part of the input: its frames [begin, end) in capture order, the pairs between them that
// are fewer than max_frame_gap frames apart in capture order, and tracks rebuilt from those
// pairs. The cameras are all kept. InvalidArgument for a range outside the frames.
MapperInput InputPart(const MapperInput& input, size_t begin, size_t end,
                      int max_frame_gap = INT_MAX);

// A reconstruction of the input's cameras and frames, none registered, no points: where
// mapping starts, and what a saved state (MappedState) is restored onto.
Reconstruction EmptyReconstruction(const MapperInput& input);

}  // namespace loopsfm
