// ReadColmapModelBinary on cameras.bin, images.bin and points3D.bin cut from one input at
// kFileSeparator (in that order).

#include "fuzz_util.h"
#include "loopsfm/storage/colmap_model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace loopsfm::fuzz;
  const auto dir = WriteModelFolder(data, size, "colmap_binary", ".bin");
  ExpectTypedErrors([&] { loopsfm::ReadColmapModelBinary(dir); });
  return 0;
}
