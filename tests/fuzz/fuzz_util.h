#pragma once
// Shared by the fuzz targets in this folder (see CMakeLists.txt): a scratch folder for the
// readers that take paths, splitting one input into several files, and the rule every
// target checks: a reader given bad bytes throws InputError or StorageError, nothing else.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "loopsfm/util/errors.h"

// libFuzzer's entry point, defined once per target.
extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace loopsfm::fuzz {

// Between the files of a multi-file input (a COLMAP model's three files).
inline constexpr std::string_view kFileSeparator = "@@next-file@@";

// A folder of this process's own (in /dev/shm when there is one), removed at exit.
const std::filesystem::path& ScratchDir();

// Writes `bytes` to ScratchDir() / name and returns the path.
std::filesystem::path WriteScratchFile(const std::string& name, std::string_view bytes);

// The input cut at kFileSeparator into exactly `n` parts: missing parts are empty, and
// the last part keeps any further separators.
std::vector<std::string_view> SplitFiles(const uint8_t* data, size_t size, size_t n);

// A COLMAP model folder ScratchDir() / folder holding cameras, images and points3D with
// `extension` (".bin" or ".txt"), their bytes cut from the input by SplitFiles.
std::filesystem::path WriteModelFolder(const uint8_t* data, size_t size, const std::string& folder,
                                       const std::string& extension);

// Runs read(); the typed errors of bad input are the expected outcome. Anything else
// (another exception, a crash, a sanitizer report) leaves this function and is a finding.
template <typename F>
void ExpectTypedErrors(F&& read) {
  try {
    read();
  } catch (const InputError&) {
  } catch (const StorageError&) {
  }
}

}  // namespace loopsfm::fuzz
