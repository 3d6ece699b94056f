// VocabularyTree::Save / Load. File layout (all little-endian):
//
//   char[8]  magic "LSFMVOCT"
//   uint32   format version (kFormatVersion)
//   uint32   descriptor dimension (128)
//   uint32   branching, depth (as trained)
//   uint32   num_nodes, num_words
//   num_nodes x (uint32 first_child, uint32 num_children)     breadth-first, node 0 = root
//   num_nodes x 128 float32 centres
//   uint64   FNV-1a hash of every byte before it

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string>
#include <string_view>

#include "loopsfm/retrieval/vocabulary_tree.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

constexpr std::string_view kMagic = "LSFMVOCT";
constexpr uint32_t kFormatVersion = 1;
constexpr size_t kHeaderBytes = 8 + 6 * sizeof(uint32_t);
constexpr size_t kNodeBytes = 2 * sizeof(uint32_t) + kDescriptorDim * sizeof(float);

uint64_t Fnv1a(const char* data, size_t size) {
  uint64_t hash = 0xcbf29ce484222325ull;
  for (size_t i = 0; i < size; ++i) {
    hash ^= static_cast<uint8_t>(data[i]);
    hash *= 0x100000001b3ull;
  }
  return hash;
}

template <typename T>
T ToLittleEndian(T value) {
  if constexpr (std::endian::native == std::endian::big) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    std::reverse(bytes, bytes + sizeof(T));
    std::memcpy(&value, bytes, sizeof(T));
  }
  return value;
}

template <typename T>
void Append(std::string& out, T value) {
  static_assert(std::is_integral_v<T>);
  value = ToLittleEndian(value);
  out.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <typename T>
T Extract(const std::string& in, size_t& pos) {
  static_assert(std::is_integral_v<T>);
  T value;
  std::memcpy(&value, in.data() + pos, sizeof(T));
  pos += sizeof(T);
  return ToLittleEndian(value);
}

}  // namespace

void VocabularyTree::Save(const std::filesystem::path& path) const {
  LOOPSFM_CHECK_MSG(!Empty(), "saving an empty vocabulary tree");
  std::string bytes(kMagic);
  bytes.reserve(kHeaderBytes + nodes_.size() * kNodeBytes + sizeof(uint64_t));
  Append<uint32_t>(bytes, kFormatVersion);
  Append<uint32_t>(bytes, kDescriptorDim);
  Append<uint32_t>(bytes, static_cast<uint32_t>(branching_));
  Append<uint32_t>(bytes, static_cast<uint32_t>(depth_));
  Append<uint32_t>(bytes, static_cast<uint32_t>(nodes_.size()));
  Append<uint32_t>(bytes, static_cast<uint32_t>(num_words_));
  for (const Node& node : nodes_) {
    Append<uint32_t>(bytes, node.first_child);
    Append<uint32_t>(bytes, node.num_children);
  }
  for (int64_t i = 0; i < centres_.size(); ++i) {
    Append<uint32_t>(bytes, std::bit_cast<uint32_t>(centres_.data()[i]));
  }
  Append<uint64_t>(bytes, Fnv1a(bytes.data(), bytes.size()));

  // Written beside the target and renamed, so a failed write never leaves half a tree.
  std::filesystem::path temp = path;
  temp += ".partial";
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(temp, ignored);
      throw StorageError(fmt::format("cannot write vocabulary tree '{}': check that the folder "
                                     "exists and is writable",
                                     path.string()));
    }
  }
  std::error_code ec;
  std::filesystem::rename(temp, path, ec);
  if (ec) {
    std::filesystem::remove(temp, ec);
    throw StorageError(fmt::format("cannot write vocabulary tree '{}': {}", path.string(),
                                   ec.message()));
  }
}

VocabularyTree VocabularyTree::Load(const std::filesystem::path& path) {
  const std::string where = fmt::format("vocabulary tree '{}'", path.string());
  std::ifstream in(path, std::ios::binary);
  std::error_code ec;
  const bool is_file = std::filesystem::is_regular_file(path, ec);
  if (!in || !is_file) {
    throw InputError(fmt::format("cannot read {}: no such file (build one with `loopsfm vocab "
                                 "build`, or leave out --vocab to train on the scene)",
                                 where));
  }
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (bytes.size() < kMagic.size() || std::string_view(bytes).substr(0, 8) != kMagic) {
    throw InputError(fmt::format("{} is not a loopsfm vocabulary tree file (no '{}' header)",
                                 where, kMagic));
  }
  if (bytes.size() < kHeaderBytes) {
    throw InputError(fmt::format("{} is truncated: {} bytes, shorter than its header", where,
                                 bytes.size()));
  }
  size_t pos = kMagic.size();
  const uint32_t version = Extract<uint32_t>(bytes, pos);
  const uint32_t dim = Extract<uint32_t>(bytes, pos);
  const uint32_t branching = Extract<uint32_t>(bytes, pos);
  const uint32_t depth = Extract<uint32_t>(bytes, pos);
  const uint32_t num_nodes = Extract<uint32_t>(bytes, pos);
  const uint32_t num_words = Extract<uint32_t>(bytes, pos);
  if (version != kFormatVersion) {
    throw InputError(fmt::format("{} has format version {}, this build reads version {}: "
                                 "rebuild it with `loopsfm vocab build`",
                                 where, version, kFormatVersion));
  }
  if (dim != kDescriptorDim) {
    throw InputError(fmt::format("{} holds {}-dimensional descriptors, expected {} (SIFT)", where,
                                 dim, kDescriptorDim));
  }
  if (num_nodes == 0) throw InputError(fmt::format("{} is corrupt: it has no nodes", where));
  const uint64_t expected = kHeaderBytes + uint64_t{num_nodes} * kNodeBytes + sizeof(uint64_t);
  if (bytes.size() < expected) {
    throw InputError(fmt::format("{} is truncated: {} bytes, expected {} for {} nodes", where,
                                 bytes.size(), expected, num_nodes));
  }
  if (bytes.size() > expected) {
    throw InputError(fmt::format("{} is corrupt: {} unexpected bytes after the tree", where,
                                 bytes.size() - expected));
  }
  size_t checksum_pos = expected - sizeof(uint64_t);
  if (Extract<uint64_t>(bytes, checksum_pos) != Fnv1a(bytes.data(), expected - sizeof(uint64_t))) {
    throw InputError(fmt::format("{} is corrupt: its checksum does not match its contents", where));
  }

  VocabularyTree tree;
  tree.branching_ = static_cast<int>(branching);
  tree.depth_ = static_cast<int>(depth);
  tree.nodes_.resize(num_nodes);
  for (Node& node : tree.nodes_) {
    node.first_child = Extract<uint32_t>(bytes, pos);
    node.num_children = Extract<uint32_t>(bytes, pos);
  }
  tree.centres_.resize(num_nodes, kDescriptorDim);
  for (int64_t i = 0; i < tree.centres_.size(); ++i) {
    tree.centres_.data()[i] = std::bit_cast<float>(Extract<uint32_t>(bytes, pos));
  }
  if (!tree.centres_.allFinite()) {
    throw InputError(fmt::format("{} is corrupt: it has non-finite centres", where));
  }
  if (!tree.Finish() || static_cast<uint32_t>(tree.num_words_) != num_words) {
    throw InputError(fmt::format("{} is corrupt: its nodes do not form a tree", where));
  }
  return tree;
}

}  // namespace loopsfm
