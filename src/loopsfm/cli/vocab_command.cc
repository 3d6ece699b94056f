#include "loopsfm/cli/commands.h"
#include "loopsfm/pipeline/vocab_build.h"
#include "loopsfm/util/logging.h"

namespace loopsfm::cli {

void AddVocabCommand(CLI::App& app) {
  struct Flags {
    std::vector<std::string> inputs;
    std::string output;
    VocabBuildOptions options;
  };
  auto flags = std::make_shared<Flags>();
  CLI::App* vocab = app.add_subcommand("vocab", "Vocabulary trees for loop detection");
  vocab->require_subcommand(1);
  CLI::App* build = vocab->add_subcommand(
      "build", "Train a vocabulary tree on databases, videos or image folders and save it");
  build->add_option("inputs", flags->inputs,
                    "Databases (.db) from `loopsfm extract`, videos or image folders")
      ->required();
  build->add_option("-o,--output", flags->output, "Tree file to write")->required();
  build->add_option("--branching", flags->options.tree.branching, "Branching factor k")
      ->capture_default_str();
  build->add_option("--depth", flags->options.tree.depth, "Depth L")->capture_default_str();
  build->add_option("--max-descriptors", flags->options.tree.max_training_descriptors,
                    "Descriptors sampled for training")
      ->capture_default_str();
  build->add_option("--every", flags->options.every, "Videos and folders: one frame in N")
      ->capture_default_str();
  build->callback([flags] {
    std::vector<std::filesystem::path> inputs(flags->inputs.begin(), flags->inputs.end());
    VocabBuildReport report;
    const VocabularyTree tree = BuildVocabulary(inputs, flags->options, &report);
    tree.Save(flags->output);
    spdlog::info("vocab: {} words (k={}, L={}) from {} descriptors of {} frames, {:.1f} s, saved "
                 "to {}",
                 report.num_words, tree.Branching(), tree.Depth(), report.num_training_descriptors,
                 report.num_frames, report.seconds, flags->output);
  });
}

}  // namespace loopsfm::cli
