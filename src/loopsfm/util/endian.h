#pragma once
// Byte order of binary files: loopsfm's files and COLMAP's binary models are little-endian.

#include <algorithm>
#include <bit>
#include <cstring>

namespace loopsfm {

// A value converted between the host's byte order and little-endian (either way: the
// conversion is its own inverse). A no-op on little-endian hosts.
template <typename T>
T ToFromLittleEndian(T value) {
  if constexpr (std::endian::native == std::endian::big) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    std::reverse(bytes, bytes + sizeof(T));
    std::memcpy(&value, bytes, sizeof(T));
  }
  return value;
}

}  // namespace loopsfm
