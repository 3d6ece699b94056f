#pragma once
// `loopsfm vocab build`: a vocabulary tree trained on any set of inputs (databases written
// by `loopsfm extract`, videos or image folders), saved for reuse with `--vocab FILE`.

#include <filesystem>
#include <vector>

#include "loopsfm/pipeline/extract.h"
#include "loopsfm/retrieval/vocabulary_tree.h"

namespace loopsfm {

struct VocabBuildOptions {
  VocabTreeOptions tree;
  // For video and folder inputs: use one frame in this many, and these SIFT settings.
  int every = 10;
  SiftOptions sift;
  // Most descriptors kept per frame before the final sample (bounds memory).
  int max_descriptors_per_frame = 500;
  uint64_t seed = kDefaultRandomSeed;
  void Check() const;
};

struct VocabBuildReport {
  size_t num_inputs = 0;
  size_t num_frames = 0;
  size_t num_training_descriptors = 0;
  int num_words = 0;
  double seconds = 0.0;
};

// Up to max_rows random rows of `all` (all of them when it has fewer), for bounded samples.
FeatureDescriptors SampleDescriptorRows(const FeatureDescriptors& all, int max_rows, Random& random);

// Inputs ending in .db are read as databases; anything else as a video or image folder.
VocabularyTree BuildVocabulary(const std::vector<std::filesystem::path>& inputs,
                               const VocabBuildOptions& options, VocabBuildReport* report);

}  // namespace loopsfm
