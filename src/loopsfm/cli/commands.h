#pragma once
// The `loopsfm` subcommands. Each Add*Command registers its flags on the app and sets a
// callback that runs the stage; the callbacks throw loopsfm::Error on bad input, which
// main() turns into a message and exit code 2.

#include <CLI/CLI.hpp>

#include "loopsfm/cli/common.h"

namespace loopsfm::cli {

void AddExtractCommand(CLI::App& app);
void AddMatchCommand(CLI::App& app);
void AddTracksCommand(CLI::App& app);
void AddSynthCommand(CLI::App& app);
void AddReconstructCommand(CLI::App& app);
void AddMapCommand(CLI::App& app);
void AddEvalCommand(CLI::App& app);
void AddVocabCommand(CLI::App& app);
void AddExportCommand(CLI::App& app);


}  // namespace loopsfm::cli
