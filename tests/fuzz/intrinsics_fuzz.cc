// ReadIntrinsicsFile on the input as an intrinsics file.

#include "fuzz_util.h"
#include "loopsfm/scene/dataset_files.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace loopsfm::fuzz;
  const auto path = WriteScratchFile("intrinsics.txt", {reinterpret_cast<const char*>(data), size});
  ExpectTypedErrors([&] { loopsfm::ReadIntrinsicsFile(path); });
  return 0;
}
