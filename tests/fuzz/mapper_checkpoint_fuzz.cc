// ReadMapperCheckpoint on the input as a mapper checkpoint file, with the fingerprint the
// seeds were written with. The reader never throws for a file's content (it returns nullopt
// and logs why), so here every exception that leaves it is a finding, InputError included:
// no ExpectTypedErrors. A checkpoint it returns holds no more frames than the file has
// bytes (each takes 60).

#include <spdlog/spdlog.h>

#include "fuzz_util.h"
#include "loopsfm/pipeline/mapper_checkpoint.h"
#include "mapper_checkpoint_fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace loopsfm::fuzz;
  // The reader warns about almost every input; the output would slow the fuzzer down.
  static const bool quiet = [] {
    spdlog::set_level(spdlog::level::off);
    return true;
  }();
  (void)quiet;
  static const nlohmann::json fingerprint = MapperCheckpointFuzzFingerprint();
  const auto path =
      WriteScratchFile("mapper_checkpoint.bin", {reinterpret_cast<const char*>(data), size});
  const std::optional<loopsfm::MapperCheckpoint> checkpoint =
      loopsfm::ReadMapperCheckpoint(path, fingerprint);
  if (checkpoint) LOOPSFM_CHECK(checkpoint->NumRegistered() < size);
  return 0;
}
