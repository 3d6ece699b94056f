#pragma once
// A track: the observations of one scene point, one feature per image.

#include <vector>

#include "loopsfm/util/types.h"

namespace loopsfm {

struct TrackElement {
  image_t image_id = kInvalidImageId;
  point2D_t point2D_idx = kInvalidPoint2DIdx;
  friend bool operator==(const TrackElement&, const TrackElement&) = default;
  friend auto operator<=>(const TrackElement&, const TrackElement&) = default;
};

struct Track {
  std::vector<TrackElement> elements;
  size_t Length() const { return elements.size(); }
};

}  // namespace loopsfm
