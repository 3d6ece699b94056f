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

#include <cmath>
#include <cstring>
#include <fstream>
#include <string>
#include <string_view>

#include "loopsfm/retrieval/vocabulary_tree.h"
#include "loopsfm/util/endian.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

constexpr std::string_view kMagic = "LSFMVOCT";
constexpr uint32_t kFormatVersion = 1;
constexpr size_t kHeaderBytes = 8 + 6 * sizeof(uint32_t);
constexpr size_t kNodeBytes = 2 * sizeof(uint32_t) + kDescriptorDim * sizeof(float);

// FNV-1a over everything written or read, in one pass.
class Fnv1a {
 public:
  void Add(const char* data, size_t size) {
    for (size_t i = 0; i < size; ++i) {
      hash_ ^= static_cast<uint8_t>(data[i]);
      hash_ *= 0x100000001b3ull;
    }
  }
  uint64_t Value() const { return hash_; }

 private:
  uint64_t hash_ = 0xcbf29ce484222325ull;
};

// Buffered little-endian writer that hashes what it writes.
class Writer {
 public:
  explicit Writer(std::ofstream& out) : out_(out) {}
  template <typename T>
  void Put(T value) {
    value = ToFromLittleEndian(value);
    buffer_.append(reinterpret_cast<const char*>(&value), sizeof(T));
    if (buffer_.size() >= (1 << 20)) Flush();
  }
  void Flush() {
    hash_.Add(buffer_.data(), buffer_.size());
    out_.write(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
    buffer_.clear();
  }
  uint64_t Hash() const { return hash_.Value(); }

 private:
  std::ofstream& out_;
  std::string buffer_;
  Fnv1a hash_;
};

// Little-endian reader of a file whose size was checked beforehand; hashes what it reads.
class Reader {
 public:
  explicit Reader(std::ifstream& in) : in_(in) {}
  template <typename T>
  T Get() {
    T value;
    in_.read(reinterpret_cast<char*>(&value), sizeof(T));
    hash_.Add(reinterpret_cast<const char*>(&value), sizeof(T));
    return ToFromLittleEndian(value);
  }
  // Reads n values of T into out, hashing them.
  template <typename T>
  void GetArray(T* out, size_t n) {
    in_.read(reinterpret_cast<char*>(out), static_cast<std::streamsize>(n * sizeof(T)));
    hash_.Add(reinterpret_cast<const char*>(out), n * sizeof(T));
    for (size_t i = 0; i < n; ++i) out[i] = ToFromLittleEndian(out[i]);
  }
  bool Good() const { return static_cast<bool>(in_); }
  uint64_t Hash() const { return hash_.Value(); }

 private:
  std::ifstream& in_;
  Fnv1a hash_;
};

}  // namespace

void VocabularyTree::Save(const std::filesystem::path& path) const {
  LOOPSFM_CHECK_MSG(!Empty(), "saving an empty vocabulary tree");
  // Written beside the target and renamed, so a failed write never leaves half a tree.
  std::filesystem::path temp = path;
  temp += ".partial";
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    Writer writer(out);
    for (const char c : kMagic) writer.Put(c);
    writer.Put<uint32_t>(kFormatVersion);
    writer.Put<uint32_t>(kDescriptorDim);
    writer.Put<uint32_t>(static_cast<uint32_t>(branching_));
    writer.Put<uint32_t>(static_cast<uint32_t>(depth_));
    writer.Put<uint32_t>(static_cast<uint32_t>(nodes_.size()));
    writer.Put<uint32_t>(static_cast<uint32_t>(num_words_));
    for (const Node& node : nodes_) {
      writer.Put<uint32_t>(node.first_child);
      writer.Put<uint32_t>(node.num_children);
    }
    for (const float value : centres_) writer.Put<float>(value);
    writer.Flush();
    const uint64_t hash = ToFromLittleEndian(writer.Hash());
    out.write(reinterpret_cast<const char*>(&hash), sizeof(hash));
    out.close();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(temp, ignored);
      throw StorageError(
          fmt::format("cannot write vocabulary tree '{}': check that the folder "
                      "exists and is writable",
                      path.string()));
    }
  }
  std::error_code ec;
  std::filesystem::rename(temp, path, ec);
  if (ec) {
    std::filesystem::remove(temp, ec);
    throw StorageError(
        fmt::format("cannot write vocabulary tree '{}': {}", path.string(), ec.message()));
  }
}

VocabularyTree VocabularyTree::Load(const std::filesystem::path& path) {
  const std::string where = fmt::format("vocabulary tree '{}'", path.string());
  std::error_code ec;
  const bool is_file = std::filesystem::is_regular_file(path, ec);
  const uint64_t size = is_file ? std::filesystem::file_size(path, ec) : 0;
  std::ifstream in(path, std::ios::binary);
  if (!is_file || ec || !in) {
    throw InputError(
        fmt::format("cannot read {}: no such file (build one with `loopsfm vocab "
                    "build`, or leave out --vocab to train on the scene)",
                    where));
  }
  Reader reader(in);
  char magic[8] = {};
  if (size >= kMagic.size()) {
    for (char& c : magic) c = reader.Get<char>();
  }
  if (!reader.Good() || std::string_view(magic, 8) != kMagic) {
    throw InputError(
        fmt::format("{} is not a loopsfm vocabulary tree file (no '{}' header)", where, kMagic));
  }
  if (size < kHeaderBytes) {
    throw InputError(
        fmt::format("{} is truncated: {} bytes, shorter than its header", where, size));
  }
  const uint32_t version = reader.Get<uint32_t>();
  const uint32_t dim = reader.Get<uint32_t>();
  const uint32_t branching = reader.Get<uint32_t>();
  const uint32_t depth = reader.Get<uint32_t>();
  const uint32_t num_nodes = reader.Get<uint32_t>();
  const uint32_t num_words = reader.Get<uint32_t>();
  if (version != kFormatVersion) {
    throw InputError(
        fmt::format("{} has format version {}, this build reads version {}: "
                    "rebuild it with `loopsfm vocab build`",
                    where, version, kFormatVersion));
  }
  if (dim != kDescriptorDim) {
    throw InputError(fmt::format("{} holds {}-dimensional descriptors, expected {} (SIFT)", where,
                                 dim, kDescriptorDim));
  }
  if (num_nodes == 0) throw InputError(fmt::format("{} is corrupt: it has no nodes", where));
  const uint64_t expected = kHeaderBytes + uint64_t{num_nodes} * kNodeBytes + sizeof(uint64_t);
  if (size < expected) {
    throw InputError(fmt::format("{} is truncated: {} bytes, expected {} for {} nodes", where, size,
                                 expected, num_nodes));
  }
  if (size > expected) {
    throw InputError(
        fmt::format("{} is corrupt: {} unexpected bytes after the tree", where, size - expected));
  }

  VocabularyTree tree;
  tree.branching_ = static_cast<int>(branching);
  tree.depth_ = static_cast<int>(depth);
  std::vector<uint32_t> links(2 * size_t{num_nodes});
  reader.GetArray(links.data(), links.size());
  tree.nodes_.resize(num_nodes);
  for (size_t i = 0; i < tree.nodes_.size(); ++i) {
    tree.nodes_[i] = {links[2 * i], links[2 * i + 1]};
  }
  tree.centres_.resize(size_t{num_nodes} * kDescriptorDim);
  reader.GetArray(tree.centres_.data(), tree.centres_.size());
  const uint64_t hash = reader.Hash();
  const uint64_t stored = reader.Get<uint64_t>();
  if (!reader.Good()) throw InputError(fmt::format("{} could not be read to its end", where));
  if (stored != hash) {
    throw InputError(fmt::format("{} is corrupt: its checksum does not match its contents", where));
  }
  for (const float value : tree.centres_) {
    if (!std::isfinite(value)) {
      throw InputError(fmt::format("{} is corrupt: it has non-finite centres", where));
    }
  }
  if (!tree.Finish() || static_cast<uint32_t>(tree.num_words_) != num_words) {
    throw InputError(fmt::format("{} is corrupt: its nodes do not form a tree", where));
  }
  return tree;
}

}  // namespace loopsfm
