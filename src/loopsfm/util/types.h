#pragma once
// Typed ids shared by every stage, with COLMAP's numbering conventions.

#include <cstdint>
#include <functional>
#include <limits>
#include <utility>

namespace loopsfm {

using camera_t = uint32_t;
using image_t = uint32_t;
using point2D_t = uint32_t;
using point3D_t = uint64_t;
using image_pair_t = uint64_t;

inline constexpr camera_t kInvalidCameraId = std::numeric_limits<camera_t>::max();
inline constexpr image_t kInvalidImageId = std::numeric_limits<image_t>::max();
inline constexpr point2D_t kInvalidPoint2DIdx = std::numeric_limits<point2D_t>::max();
inline constexpr point3D_t kInvalidPoint3DId = std::numeric_limits<point3D_t>::max();

// COLMAP's bound on image ids, used to pack an unordered pair into one integer.
inline constexpr uint64_t kMaxNumImages = 2147483647;

// An unordered pair of images, stored with image_id1 < image_id2.
struct ImagePair {
  image_t image_id1 = kInvalidImageId;
  image_t image_id2 = kInvalidImageId;

  ImagePair() = default;
  ImagePair(image_t a, image_t b) : image_id1(a < b ? a : b), image_id2(a < b ? b : a) {}
  friend bool operator==(const ImagePair&, const ImagePair&) = default;
  friend auto operator<=>(const ImagePair&, const ImagePair&) = default;
};

// COLMAP's pair id: id1 * kMaxNumImages + id2 with id1 < id2.
inline image_pair_t PairToPairId(image_t a, image_t b) {
  if (a > b) std::swap(a, b);
  return static_cast<image_pair_t>(a) * kMaxNumImages + b;
}
inline image_pair_t PairToPairId(const ImagePair& pair) {
  return PairToPairId(pair.image_id1, pair.image_id2);
}
inline ImagePair PairIdToPair(image_pair_t pair_id) {
  return ImagePair(static_cast<image_t>(pair_id / kMaxNumImages),
                   static_cast<image_t>(pair_id % kMaxNumImages));
}
// True when the pair must be swapped to be stored in COLMAP's order.
inline bool SwapImagePair(image_t a, image_t b) { return a > b; }

}  // namespace loopsfm

template <>
struct std::hash<loopsfm::ImagePair> {
  size_t operator()(const loopsfm::ImagePair& p) const noexcept {
    return std::hash<uint64_t>()(loopsfm::PairToPairId(p));
  }
};
