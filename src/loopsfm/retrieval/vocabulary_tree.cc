#include "loopsfm/retrieval/vocabulary_tree.h"

#include <algorithm>
#include <cstring>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "loopsfm/retrieval/kmeans.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

constexpr uint32_t kNoWord = std::numeric_limits<uint32_t>::max();
// QuantizeAll descends node by node while at least this many descriptors share a node.
constexpr size_t kMinGroupedDescent = 64;

// A node whose descriptors are rows [begin, end) of the (reordered) training matrix.
struct PendingNode {
  uint32_t node;
  int64_t begin, end;
};

// Reorders rows [begin, begin + labels.size()) of `data` by cluster (stable), so that each
// cluster's rows are contiguous, in cluster order.
void PartitionRows(FeatureDescriptors& data, int64_t begin, const KMeansResult& split) {
  const int64_t count = static_cast<int64_t>(split.labels.size());
  std::vector<int64_t> next(split.sizes.size(), 0);
  for (size_t j = 1; j < next.size(); ++j) next[j] = next[j - 1] + split.sizes[j - 1];
  FeatureDescriptors sorted(count, kDescriptorDim);
  for (int64_t i = 0; i < count; ++i) {
    sorted.row(next[split.labels[i]]++) = data.row(begin + i);
  }
  data.middleRows(begin, count) = sorted;
}

}  // namespace

void VocabTreeOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(branching >= 2 && branching <= 4096,
                         "vocabulary tree branching factor must be between 2 and 4096, got {}",
                         branching);
  LOOPSFM_REQUIRE_OPTION(depth >= 1 && depth <= 16,
                         "vocabulary tree depth must be between 1 and 16, got {}", depth);
  LOOPSFM_REQUIRE_OPTION(max_training_descriptors >= branching,
                         "vocabulary tree needs at least `branching` ({}) training descriptors, "
                         "got max_training_descriptors = {}",
                         branching, max_training_descriptors);
  LOOPSFM_REQUIRE_OPTION(kmeans_iterations >= 0 && kmeans_iterations <= 1000,
                         "k-means iterations must be between 0 and 1000, got {}",
                         kmeans_iterations);
}

FeatureDescriptors SampleDescriptors(const std::vector<const FeatureDescriptors*>& descriptor_sets,
                                     int max_descriptors, Random& random) {
  LOOPSFM_REQUIRE_OPTION(max_descriptors >= 0,
                         "descriptor sample size must be non-negative, got {}", max_descriptors);
  int64_t total = 0;
  for (const FeatureDescriptors* set : descriptor_sets) {
    LOOPSFM_CHECK(set != nullptr);
    total += set->rows();
  }
  LOOPSFM_REQUIRE_OPTION(total <= std::numeric_limits<uint32_t>::max(),
                         "too many descriptors to sample from ({})", total);
  std::vector<uint32_t> picked;
  if (total <= max_descriptors) {
    picked.resize(total);
    for (int64_t i = 0; i < total; ++i) picked[i] = static_cast<uint32_t>(i);
  } else {
    picked = random.Sample(static_cast<uint32_t>(total), static_cast<uint32_t>(max_descriptors));
    std::sort(picked.begin(), picked.end());
  }
  FeatureDescriptors sample(static_cast<int64_t>(picked.size()), kDescriptorDim);
  size_t set_index = 0;
  int64_t set_begin = 0;
  for (size_t i = 0; i < picked.size(); ++i) {
    while (picked[i] >= set_begin + descriptor_sets[set_index]->rows()) {
      set_begin += descriptor_sets[set_index]->rows();
      ++set_index;
    }
    sample.row(static_cast<int64_t>(i)) = descriptor_sets[set_index]->row(picked[i] - set_begin);
  }
  return sample;
}

VocabularyTree VocabularyTree::Train(const std::vector<const FeatureDescriptors*>& descriptor_sets,
                                     const VocabTreeOptions& options, Random& random) {
  options.Check();
  return Train(SampleDescriptors(descriptor_sets, options.max_training_descriptors, random),
               options, random);
}

VocabularyTree VocabularyTree::Train(FeatureDescriptors data, const VocabTreeOptions& options,
                                     Random& random) {
  options.Check();
  if (data.rows() == 0) {
    throw InvalidArgument("cannot train a vocabulary tree without descriptors");
  }
  // `data` is reordered level by level so that the descriptors of every node are contiguous.
  // Each node draws from its own generator, derived from its (breadth-first) id, so that nodes
  // can be split in any order.
  const Random base(random.Engine()());
  KMeansOptions kmeans_options;
  kmeans_options.num_clusters = options.branching;
  kmeans_options.max_iterations = options.kmeans_iterations;

  VocabularyTree tree;
  tree.branching_ = options.branching;
  tree.depth_ = options.depth;
  tree.nodes_.emplace_back();
  tree.centres_.assign(kDescriptorDim, 0.0f);  // the root's centre is unused
  std::vector<PendingNode> level = {{0, 0, data.rows()}};
  for (int depth = 0; depth < options.depth && !level.empty(); ++depth) {
    std::vector<KMeansResult> splits(level.size());
    tbb::parallel_for(size_t{0}, level.size(), [&](size_t i) {
      const PendingNode& pending = level[i];
      const int64_t count = pending.end - pending.begin;
      if (count < options.branching) return;  // too few to split: a leaf
      Random node_random = base.Derive(pending.node);
      KMeansResult split =
          KMeans(data.data() + pending.begin * kDescriptorDim, count, kmeans_options, node_random);
      if (split.centres.rows() < 2) return;  // all descriptors equal: a leaf
      PartitionRows(data, pending.begin, split);
      split.labels = {};
      splits[i] = std::move(split);
    });
    std::vector<PendingNode> next;
    size_t num_new = 0;
    for (const KMeansResult& split : splits) num_new += split.centres.rows();
    tree.centres_.reserve(tree.centres_.size() + num_new * kDescriptorDim);
    for (size_t i = 0; i < level.size(); ++i) {
      KMeansResult& split = splits[i];
      const int num_children = static_cast<int>(split.centres.rows());
      if (num_children == 0) continue;
      tree.nodes_[level[i].node] = {static_cast<uint32_t>(tree.nodes_.size()),
                                    static_cast<uint32_t>(num_children)};
      int64_t begin = level[i].begin;
      for (int j = 0; j < num_children; ++j) {
        next.push_back({static_cast<uint32_t>(tree.nodes_.size()), begin, begin + split.sizes[j]});
        begin += split.sizes[j];
        tree.nodes_.emplace_back();
        tree.centres_.insert(tree.centres_.end(), split.centres.row(j).data(),
                             split.centres.row(j).data() + kDescriptorDim);
      }
      split = KMeansResult();  // frees its centres
    }
    level = std::move(next);
  }
  LOOPSFM_CHECK(tree.Finish());
  return tree;
}

bool VocabularyTree::Finish() {
  if (nodes_.empty() || centres_.size() != nodes_.size() * kDescriptorDim) return false;
  // Breadth-first layout: the children of the nodes, in node order, are nodes 1, 2, ...
  uint64_t expected_child = 1;
  num_words_ = 0;
  node_word_.assign(nodes_.size(), kNoWord);
  word_node_.clear();
  for (size_t i = 0; i < nodes_.size(); ++i) {
    const Node& node = nodes_[i];
    if (node.num_children == 0) {
      node_word_[i] = static_cast<uint32_t>(word_node_.size());
      word_node_.push_back(static_cast<uint32_t>(i));
      continue;
    }
    if (node.first_child != expected_child) return false;
    expected_child += node.num_children;
    if (expected_child > nodes_.size()) return false;
  }
  if (expected_child != nodes_.size()) return false;
  num_words_ = static_cast<int>(word_node_.size());
  squared_norms_.resize(nodes_.size());
  for (size_t i = 0; i < nodes_.size(); ++i) {
    squared_norms_[i] = internal::SquaredNorm128(Centre(static_cast<uint32_t>(i)));
  }
  return true;
}

uint32_t VocabularyTree::Quantize(const uint8_t* descriptor) const {
  LOOPSFM_CHECK_MSG(!Empty(), "quantising with an empty vocabulary tree");
  return DescendOne(0, descriptor);
}

uint32_t VocabularyTree::DescendOne(uint32_t node, const uint8_t* descriptor) const {
  alignas(64) float x[kDescriptorDim];
  internal::ToFloat(descriptor, x);
  uint32_t index = node;
  while (nodes_[index].num_children > 0) {
    const Node& current = nodes_[index];
    index =
        current.first_child + internal::NearestCentre(x, Centre(current.first_child),
                                                      squared_norms_.data() + current.first_child,
                                                      static_cast<int>(current.num_children));
  }
  return node_word_[index];
}

void VocabularyTree::Descend(uint32_t node, const uint8_t* const* rows, uint32_t* indices,
                             uint32_t* scratch, uint32_t* labels, size_t count,
                             uint32_t* words) const {
  const Node& parent = nodes_[node];
  if (parent.num_children == 0) {
    for (size_t i = 0; i < count; ++i) words[indices[i]] = node_word_[node];
    return;
  }
  if (count < kMinGroupedDescent) {  // too few to share centres: one at a time
    for (size_t i = 0; i < count; ++i) words[indices[i]] = DescendOne(node, rows[indices[i]]);
    return;
  }
  const int k = static_cast<int>(parent.num_children);
  const float* centres = Centre(parent.first_child);
  const float* norms = squared_norms_.data() + parent.first_child;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 256), [&](const auto& range) {
    alignas(64) float x[kDescriptorDim];
    for (size_t i = range.begin(); i < range.end(); ++i) {
      internal::ToFloat(rows[indices[i]], x);
      labels[i] = static_cast<uint32_t>(internal::NearestCentre(x, centres, norms, k));
    }
  });
  // Counting sort of the indices by child, then each child's range in turn (in parallel).
  std::vector<size_t> begin(k + 1, 0);
  for (size_t i = 0; i < count; ++i) ++begin[labels[i] + 1];
  for (int j = 0; j < k; ++j) begin[j + 1] += begin[j];
  std::vector<size_t> next(begin.begin(), begin.end() - 1);
  for (size_t i = 0; i < count; ++i) scratch[next[labels[i]]++] = indices[i];
  std::copy(scratch, scratch + count, indices);
  tbb::parallel_for(0, k, [&](int j) {
    if (begin[j + 1] == begin[j]) return;
    Descend(parent.first_child + j, rows, indices + begin[j], scratch + begin[j], labels + begin[j],
            begin[j + 1] - begin[j], words);
  });
}

std::vector<uint32_t> VocabularyTree::QuantizeAll(const FeatureDescriptors& descriptors) const {
  return QuantizeAll(std::vector<const FeatureDescriptors*>{&descriptors})[0];
}

std::vector<std::vector<uint32_t>> VocabularyTree::QuantizeAll(
    const std::vector<const FeatureDescriptors*>& descriptor_sets) const {
  LOOPSFM_CHECK_MSG(!Empty(), "quantising with an empty vocabulary tree");
  std::vector<const uint8_t*> rows;
  for (const FeatureDescriptors* set : descriptor_sets) {
    LOOPSFM_CHECK(set != nullptr);
    for (int64_t i = 0; i < set->rows(); ++i) rows.push_back(set->row(i).data());
  }
  LOOPSFM_CHECK_LT(rows.size(), size_t{std::numeric_limits<uint32_t>::max()});
  std::vector<uint32_t> indices(rows.size()), scratch(rows.size()), labels(rows.size());
  std::vector<uint32_t> all_words(rows.size());
  for (size_t i = 0; i < rows.size(); ++i) indices[i] = static_cast<uint32_t>(i);
  if (!rows.empty()) {
    Descend(0, rows.data(), indices.data(), scratch.data(), labels.data(), rows.size(),
            all_words.data());
  }
  std::vector<std::vector<uint32_t>> words;
  size_t offset = 0;
  for (const FeatureDescriptors* set : descriptor_sets) {
    words.emplace_back(all_words.begin() + offset, all_words.begin() + offset + set->rows());
    offset += set->rows();
  }
  return words;
}

Eigen::Matrix<float, kDescriptorDim, 1> VocabularyTree::WordCentre(uint32_t word) const {
  LOOPSFM_CHECK_LT(word, word_node_.size());
  return Eigen::Map<const Eigen::Matrix<float, kDescriptorDim, 1>>(Centre(word_node_[word]));
}

bool operator==(const VocabularyTree& a, const VocabularyTree& b) {
  if (a.branching_ != b.branching_ || a.depth_ != b.depth_ || a.nodes_.size() != b.nodes_.size() ||
      a.centres_.size() != b.centres_.size()) {
    return false;
  }
  for (size_t i = 0; i < a.nodes_.size(); ++i) {
    if (a.nodes_[i].first_child != b.nodes_[i].first_child ||
        a.nodes_[i].num_children != b.nodes_[i].num_children) {
      return false;
    }
  }
  return a.centres_.empty() ||
         std::memcmp(a.centres_.data(), b.centres_.data(), a.centres_.size() * sizeof(float)) == 0;
}

}  // namespace loopsfm
