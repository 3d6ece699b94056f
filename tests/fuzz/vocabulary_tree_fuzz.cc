// VocabularyTree::Load on the input as a tree file, then quantising two descriptors with
// what it loaded. The trailing checksum is recomputed over the input first, so the fuzzer
// reaches the checks behind it (a real file with a bad checksum is refused before them).

#include <array>
#include <string>

#include "fuzz_util.h"
#include "loopsfm/retrieval/vocabulary_tree.h"

namespace {
// FNV-1a, as in vocabulary_tree_io.cc (little-endian hosts).
void FixChecksum(std::string& bytes) {
  constexpr size_t kHeaderBytes = 32;
  if (bytes.size() < kHeaderBytes + sizeof(uint64_t)) return;
  uint64_t hash = 0xcbf29ce484222325ull;
  const size_t body = bytes.size() - sizeof(uint64_t);
  for (size_t i = 0; i < body; ++i) {
    hash ^= static_cast<uint8_t>(bytes[i]);
    hash *= 0x100000001b3ull;
  }
  bytes.replace(body, sizeof(hash), reinterpret_cast<const char*>(&hash), sizeof(hash));
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace loopsfm::fuzz;
  std::string bytes(reinterpret_cast<const char*>(data), size);
  FixChecksum(bytes);
  const auto path = WriteScratchFile("vocabulary_tree.bin", bytes);
  ExpectTypedErrors([&] {
    const loopsfm::VocabularyTree tree = loopsfm::VocabularyTree::Load(path);
    std::array<uint8_t, loopsfm::kDescriptorDim> descriptor{};
    const uint32_t word0 = tree.Quantize(descriptor.data());
    descriptor.fill(255);
    const uint32_t word1 = tree.Quantize(descriptor.data());
    LOOPSFM_CHECK(word0 < static_cast<uint32_t>(tree.NumWords()) &&
                  word1 < static_cast<uint32_t>(tree.NumWords()));
    tree.WordCentre(word1);
  });
  return 0;
}
