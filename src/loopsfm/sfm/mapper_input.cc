#include "loopsfm/sfm/mapper_input.h"

#include <cstdlib>
#include <unordered_map>

#include "loopsfm/tracks/track_builder.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {

Reconstruction EmptyReconstruction(const MapperInput& input) {
  Reconstruction reconstruction;
  for (const Camera& camera : input.cameras) reconstruction.AddCamera(camera);
  for (const MapperFrame& frame : input.frames) {
    Image image;
    image.image_id = frame.image_id;
    image.camera_id = frame.camera_id;
    image.name = frame.name;
    image.points2D.resize(frame.points2D.size());
    for (size_t i = 0; i < frame.points2D.size(); ++i) image.points2D[i].xy = frame.points2D[i];
    reconstruction.AddImage(std::move(image));
  }
  return reconstruction;
}

MapperInput InputPart(const MapperInput& input, size_t begin, size_t end, int max_frame_gap) {
  if (begin > end || end > input.frames.size()) {
    throw InvalidArgument(fmt::format("input part: frames [{}, {}) are not a part of the {} frames",
                                      begin, end, input.frames.size()));
  }
  std::unordered_map<image_t, int> index;
  std::unordered_map<image_t, size_t> num_points2D;
  MapperInput part;
  part.cameras = input.cameras;
  for (size_t i = begin; i < end; ++i) {
    index[input.frames[i].image_id] = static_cast<int>(i);
    num_points2D[input.frames[i].image_id] = input.frames[i].points2D.size();
    part.frames.push_back(input.frames[i]);
  }
  for (const MapperPair& pair : input.pairs) {
    const auto a = index.find(pair.pair.image_id1), b = index.find(pair.pair.image_id2);
    if (a != index.end() && b != index.end() && std::abs(a->second - b->second) < max_frame_gap) {
      part.pairs.push_back(pair);
    }
  }
  std::vector<VerifiedPairMatches> verified;
  for (const MapperPair& pair : part.pairs) {
    verified.push_back({pair.pair, &pair.geometry.inlier_matches});
  }
  part.tracks = BuildTracks(num_points2D, verified, {}, nullptr);
  return part;
}

}  // namespace loopsfm
