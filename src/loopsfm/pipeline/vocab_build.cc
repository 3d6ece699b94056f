#include "loopsfm/pipeline/vocab_build.h"

#include "loopsfm/storage/database.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"
#include "loopsfm/video/keyframes.h"

namespace loopsfm {

void VocabBuildOptions::Check() const {
  tree.Check();
  sift.Check();
  LOOPSFM_REQUIRE_OPTION(every >= 1, "--every must be at least 1, got {}", every);
  LOOPSFM_REQUIRE_OPTION(max_descriptors_per_frame >= 1,
                         "descriptors per frame must be positive, got {}",
                         max_descriptors_per_frame);
}

FeatureDescriptors SampleDescriptorRows(const FeatureDescriptors& all, int max_rows, Random& random) {
  const auto rows = random.Sample(static_cast<uint32_t>(all.rows()),
                                  static_cast<uint32_t>(std::min<long>(max_rows, all.rows())));
  FeatureDescriptors sample(rows.size(), kDescriptorDim);
  for (size_t r = 0; r < rows.size(); ++r) sample.row(r) = all.row(rows[r]);
  return sample;
}

VocabularyTree BuildVocabulary(const std::vector<std::filesystem::path>& inputs,
                               const VocabBuildOptions& options, VocabBuildReport* report) {
  options.Check();
  if (inputs.empty()) throw InvalidArgument("vocab build needs at least one input");
  Timer timer;
  Random random(options.seed);
  VocabBuildReport local;
  std::vector<FeatureDescriptors> per_frame;
  for (const auto& input : inputs) {
    ++local.num_inputs;
    if (input.extension() == ".db") {
      if (!std::filesystem::exists(input)) {
        throw InputError(fmt::format("database '{}' does not exist", input.string()));
      }
      const Database database = Database::Open(input.string());
      for (const Frame& frame : database.ReadFrames()) {
        per_frame.push_back(
            SampleDescriptorRows(database.ReadDescriptors(frame.image_id), options.max_descriptors_per_frame, random));
        ++local.num_frames;
      }
    } else {
      std::unique_ptr<FrameSource> source = OpenFrameSource(input);
      KeyframeOptions keyframes;
      keyframes.mode = KeyframeMode::kWindows;
      keyframes.every = options.every;
      KeyframeSelector selector(*source, keyframes);
      while (auto keyframe = selector.Next()) {
        per_frame.push_back(SampleDescriptorRows(ExtractSift(keyframe->frame.image, options.sift).descriptors,
                                       options.max_descriptors_per_frame, random));
        ++local.num_frames;
      }
    }
    spdlog::info("vocab: read {} ({} frames so far)", input.string(), local.num_frames);
  }
  std::vector<const FeatureDescriptors*> sets;
  for (const auto& d : per_frame) sets.push_back(&d);
  FeatureDescriptors training =
      SampleDescriptors(sets, options.tree.max_training_descriptors, random);
  local.num_training_descriptors = training.rows();
  VocabularyTree tree = VocabularyTree::Train(std::move(training), options.tree, random);
  local.num_words = tree.NumWords();
  local.seconds = timer.ElapsedSeconds();
  if (report) *report = local;
  return tree;
}

}  // namespace loopsfm
