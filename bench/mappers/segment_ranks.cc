// Segment mapping shared between ranks, timed: the ranks are threads of this process
// (InProcessRanks, the path MPI ranks take, without the messages' transport), each with
// --threads threads of its own, as machines of a cluster would have. It reads a mapper
// input written by bench_mapper_input, so it needs no video, database or OpenCV codecs and
// runs on a bare machine with a few libraries beside it.
//
//   bench_segment_ranks INPUT.bin --segments N --ranks 1,2,4 [--threads T] [--runs K]
//
// Prints, per rank count, the median wall-clock time of MapInSegments over the runs, the
// frames registered in the largest model and the number of models, as JSON lines.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include <tbb/global_control.h>

#include "loopsfm/pipeline/segment_mapping.h"
#include "loopsfm/pipeline/wire_format.h"
#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

std::vector<int> ParseList(const std::string& text) {
  std::vector<int> values;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = std::min(text.find(',', start), text.size());
    values.push_back(std::atoi(text.substr(start, comma - start).c_str()));
    start = comma + 1;
  }
  return values;
}

int Main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s INPUT.bin --segments N --ranks 1,2,4 [--threads T] "
                         "[--runs K]\n", argv[0]);
    return 2;
  }
  int num_segments = 4, threads = 4, runs = 3;
  std::vector<int> rank_counts = {1, 2, 4};
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--segments") num_segments = std::atoi(value.c_str());
    else if (flag == "--ranks") rank_counts = ParseList(value);
    else if (flag == "--threads") threads = std::atoi(value.c_str());
    else if (flag == "--runs") runs = std::atoi(value.c_str());
    else {
      std::fprintf(stderr, "unknown flag %s\n", flag.c_str());
      return 2;
    }
  }
  std::ifstream in(argv[1], std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ByteReader reader(bytes);
  const MapperInput input = GetMapperInput(reader);
  SetupLogging(Verbosity::kQuiet);

  int max_ranks = 1;
  for (int r : rank_counts) max_ranks = std::max(max_ranks, r);
  tbb::global_control pool(tbb::global_control::max_allowed_parallelism,
                           size_t(max_ranks) * (threads + 1));
  IncrementalMapperOptions mapper_options;
  mapper_options.num_threads = threads;
  for (int num_ranks : rank_counts) {
    std::vector<double> seconds;
    size_t registered = 0, num_models = 0;
    for (int run = 0; run < runs; ++run) {
      auto ranks = InProcessRanks(num_ranks);
      std::vector<std::thread> workers;
      for (int r = 1; r < num_ranks; ++r) {
        workers.emplace_back([&ranks, r, threads] {
          ServeWork(*ranks[r], {{WorkKind::kMapSegment, SegmentWorkHandler()}}, threads);
        });
      }
      Timer timer;
      std::vector<Reconstruction> models;
      {
        WorkSharing sharing(ranks[0].get(), threads);
        SegmentMappingOptions options;
        options.num_segments = num_segments;
        options.sharing = num_ranks > 1 ? &sharing : nullptr;
        models = MapInSegments(input, mapper_options, options, nullptr, nullptr);
      }
      seconds.push_back(timer.ElapsedSeconds());
      for (std::thread& worker : workers) worker.join();
      registered = models.empty() ? 0 : models[0].NumRegImages();
      num_models = models.size();
    }
    std::sort(seconds.begin(), seconds.end());
    std::printf("{\"ranks\": %d, \"threads_per_rank\": %d, \"segments\": %d, \"frames\": %zu, "
                "\"registered\": %zu, \"models\": %zu, \"median_seconds\": %.2f, "
                "\"seconds\": [",
                num_ranks, threads, num_segments, input.frames.size(), registered, num_models,
                seconds[seconds.size() / 2]);
    for (size_t k = 0; k < seconds.size(); ++k) {
      std::printf("%s%.2f", k ? ", " : "", seconds[k]);
    }
    std::printf("]}\n");
    std::fflush(stdout);
  }
  return 0;
}

}  // namespace
}  // namespace loopsfm

int main(int argc, char** argv) { return loopsfm::Main(argc, argv); }
