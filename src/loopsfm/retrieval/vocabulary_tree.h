#pragma once
// Vocabulary tree (Nister & Stewenius, "Scalable recognition with a vocabulary tree", CVPR
// 2006): hierarchical k-means over SIFT descriptors. The root's descriptors are split into k
// clusters by k-means, each cluster again into k, down to depth L; the leaves are the visual
// words. A descriptor is quantised by greedy descent: at each node, go to the nearest child
// centre. Cost per descriptor: k * L distance evaluations, for up to k^L words.
//
// A tree is trained once (on a sample of the scene's own descriptors, or on any collection for
// a generic tree) and saved to a binary file that later runs load: 520 bytes per node, about
// 130 MB for the default 64 x 3 tree trained on 500k descriptors (~250k words).

#include <cstdint>
#include <filesystem>
#include <vector>

#include <Eigen/Core>

#include "loopsfm/math/random.h"
#include "loopsfm/scene/features.h"

namespace loopsfm {

// Defaults chosen with bench/retrieval/retrieval_study on real sequences: retrieval improves
// with the number of words up to a few descriptors per word, and for a given training sample a
// broad, shallow tree retrieves more temporal neighbours than a narrow, deep one, at a higher
// training and quantisation cost; the number of Lloyd iterations barely matters (figures:
// docs/benchmarks.md, "Vocabulary tree").
struct VocabTreeOptions {
  // Branching factor k: number of children of each inner node.
  int branching = 64;
  // Depth L: levels of k-means below the root; the tree has at most k^L leaves (words).
  int depth = 3;
  // Descriptors the tree is trained on, sampled uniformly from the inputs when they hold
  // more; memory is 128 bytes per descriptor. A node with fewer than `branching` of them
  // becomes a leaf, so small scenes get fewer words.
  int max_training_descriptors = 500000;
  // Maximum Lloyd iterations of each node's k-means (each stops earlier once stable).
  int kmeans_iterations = 10;
  // Throws loopsfm::InvalidArgument with a readable message.
  void Check() const;
};

// Picks up to max_descriptors rows uniformly without replacement from the union of the sets
// (all of them, in order, when they hold no more than that), returned in input order.
FeatureDescriptors SampleDescriptors(const std::vector<const FeatureDescriptors*>& descriptor_sets,
                                     int max_descriptors, Random& random);

class VocabularyTree {
 public:
  // An empty tree (NumWords() == 0); Train or Load to get a usable one.
  VocabularyTree() = default;

  // Hierarchical k-means over `descriptors` (all of them, ignoring max_training_descriptors:
  // sample first for large sets; taken by value and reordered in place, so move a sample in).
  // Nodes with fewer than `branching` descriptors, or whose descriptors are all equal, become
  // leaves early. Deterministic for a given state of `random`, whatever the thread count;
  // advances `random`. Throws InvalidArgument for bad options or no descriptors.
  static VocabularyTree Train(FeatureDescriptors descriptors, const VocabTreeOptions& options,
                              Random& random);
  // Samples options.max_training_descriptors from the sets (SampleDescriptors), then trains.
  static VocabularyTree Train(const std::vector<const FeatureDescriptors*>& descriptor_sets,
                              const VocabTreeOptions& options, Random& random);

  bool Empty() const { return nodes_.empty(); }
  // Number of visual words (leaves); word ids are 0 .. NumWords() - 1.
  int NumWords() const { return num_words_; }
  // Number of nodes including the root.
  int NumNodes() const { return static_cast<int>(nodes_.size()); }
  // Branching factor and depth the tree was trained with.
  int Branching() const { return branching_; }
  int Depth() const { return depth_; }

  // Word of one 128-byte descriptor, by greedy descent. Thread-safe.
  uint32_t Quantize(const uint8_t* descriptor) const;
  // Word of each row, equal to Quantize row by row. Descends with all the descriptors that
  // reach a node together, so its centres are read from memory once: much faster than
  // Quantize in a loop for large trees, and faster still for many images in one call.
  std::vector<uint32_t> QuantizeAll(const FeatureDescriptors& descriptors) const;
  // Words of each set (e.g. every image of a scene) in one descent.
  std::vector<std::vector<uint32_t>> QuantizeAll(
      const std::vector<const FeatureDescriptors*>& descriptor_sets) const;

  // Centre of a word's leaf (the mean of the training descriptors that reached it).
  Eigen::Matrix<float, kDescriptorDim, 1> WordCentre(uint32_t word) const;

  // Binary file: magic "LSFMVOCT", format version, shape, nodes, float32 centres (all
  // little-endian), and a checksum. Throws StorageError when the file cannot be written.
  void Save(const std::filesystem::path& path) const;
  // Throws InputError, naming the file and the problem, when it is missing, not a vocabulary
  // tree, of an unknown version, truncated or corrupt.
  static VocabularyTree Load(const std::filesystem::path& path);

  // True when both trees have the same structure and bit-identical centres.
  friend bool operator==(const VocabularyTree& a, const VocabularyTree& b);

 private:
  struct Node {
    uint32_t first_child = 0;   // children are nodes first_child .. first_child + num_children - 1
    uint32_t num_children = 0;  // 0 for a leaf
  };
  // Sends the descriptors rows[indices[0 .. count)] down from `node`, writing their words to
  // words[index]; reorders indices (scratch and labels are work space of the same size).
  void Descend(uint32_t node, const uint8_t* const* rows, uint32_t* indices, uint32_t* scratch,
               uint32_t* labels, size_t count, uint32_t* words) const;
  // Word of one descriptor, descending from `node`.
  uint32_t DescendOne(uint32_t node, const uint8_t* descriptor) const;
  // Numbers the leaves in node order and fills the derived arrays. False when the nodes do not
  // form a breadth-first tree matching the centres.
  bool Finish();

  const float* Centre(uint32_t node) const {
    return centres_.data() + size_t{node} * kDescriptorDim;
  }

  int branching_ = 0;
  int depth_ = 0;
  int num_words_ = 0;
  std::vector<Node> nodes_;           // breadth-first; node 0 is the root
  std::vector<float> centres_;        // 128 floats per node (the root's are unused)
  std::vector<float> squared_norms_;  // |centre|^2 per node
  std::vector<uint32_t> node_word_;   // word of a leaf, kNoWord for inner nodes
  std::vector<uint32_t> word_node_;   // node of each word
};

}  // namespace loopsfm
