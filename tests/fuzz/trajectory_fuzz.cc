// ReadTrajectoryFile on the input as a ground-truth trajectory file.

#include "fuzz_util.h"
#include "loopsfm/scene/dataset_files.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace loopsfm::fuzz;
  const auto path = WriteScratchFile("trajectory.txt", {reinterpret_cast<const char*>(data), size});
  ExpectTypedErrors([&] { loopsfm::ReadTrajectoryFile(path); });
  return 0;
}
