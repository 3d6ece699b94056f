#pragma once
// The input of database_blob_fuzz: one row of a COLMAP database table, with every value
// (counts, ids, blobs) taken from the fuzz bytes. Layout:
//   uint8  table (modulo kNumTables): cameras, keypoints, descriptors, matches,
//          two_view_geometries
//   4 x int64 little-endian: cameras: model, width, height, prior_focal_length;
//          the other tables: rows, cols, config (two-view geometries only), unused
//   5 x (uint16 length, bytes): two-view geometries: F, E, H, qvec, tvec; unused otherwise
//   the rest: cameras: params; the other tables: data
// A short input reads as zeros and empty blobs. Encode() writes the seed corpus.

#include <array>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace loopsfm::fuzz {

struct DatabaseFuzzRow {
  static constexpr int kNumTables = 5;
  enum Table { kCameras, kKeypoints, kDescriptors, kMatches, kTwoViewGeometries };

  int table = kCameras;
  std::array<int64_t, 4> ints{};
  std::array<std::string, 5> blobs;
  std::string data;

  static DatabaseFuzzRow Decode(std::string_view bytes) {
    DatabaseFuzzRow row;
    auto take = [&bytes](size_t n) {
      const std::string_view part = bytes.substr(0, n);
      bytes.remove_prefix(part.size());
      return part;
    };
    const std::string_view table = take(1);
    row.table = table.empty() ? 0 : static_cast<uint8_t>(table[0]) % kNumTables;
    for (int64_t& value : row.ints) {
      const std::string_view part = take(sizeof(value));
      uint64_t bits = 0;
      for (size_t i = 0; i < part.size(); ++i) bits |= uint64_t{uint8_t(part[i])} << (8 * i);
      std::memcpy(&value, &bits, sizeof(value));
    }
    for (std::string& blob : row.blobs) {
      const std::string_view length = take(2);
      size_t n = 0;
      for (size_t i = 0; i < length.size(); ++i) n |= size_t{uint8_t(length[i])} << (8 * i);
      blob = take(n);
    }
    row.data = bytes;
    return row;
  }

  std::string Encode() const {
    std::string bytes(1, static_cast<char>(table));
    for (const int64_t value : ints) {
      uint64_t bits;
      std::memcpy(&bits, &value, sizeof(bits));
      for (int i = 0; i < 8; ++i) bytes.push_back(static_cast<char>(bits >> (8 * i)));
    }
    for (const std::string& blob : blobs) {
      bytes.push_back(static_cast<char>(blob.size() & 0xff));
      bytes.push_back(static_cast<char>(blob.size() >> 8));
      bytes += blob;
    }
    return bytes + data;
  }
};

}  // namespace loopsfm::fuzz
