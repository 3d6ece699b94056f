// Writes the mapper input of a loopsfm database (tracks from its verified pairs, and with
// --self-calibrate the focal lengths self-calibration estimates, as `reconstruct` does
// without intrinsics) to a file, for bench_segment_ranks.
//
//   bench_mapper_input DATABASE OUT.bin [--self-calibrate]

#include <cstdio>
#include <fstream>
#include <string>

#include "loopsfm/pipeline/reconstruct.h"
#include "loopsfm/pipeline/wire_format.h"
#include "loopsfm/sfm/self_calibration.h"

int main(int argc, char** argv) {
  using namespace loopsfm;
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s DATABASE OUT.bin [--self-calibrate]\n", argv[0]);
    return 2;
  }
  const Database database = Database::Open(argv[1]);
  TrackBuildReport tracks;
  MapperInput input = LoadMapperInput(database, &tracks);
  if (argc > 3 && std::string(argv[3]) == "--self-calibrate") SelfCalibrate({}, &input);
  ByteWriter writer;
  PutMapperInput(writer, input);
  std::ofstream out(argv[2], std::ios::binary);
  out.write(writer.Bytes().data(), static_cast<std::streamsize>(writer.Bytes().size()));
  std::printf("%zu frames, %zu pairs, %zu tracks\n", input.frames.size(), input.pairs.size(),
              input.tracks.size());
  return out ? 0 : 1;
}
