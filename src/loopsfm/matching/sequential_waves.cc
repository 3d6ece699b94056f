#include "loopsfm/matching/sequential_waves.h"

#include <algorithm>

#include "loopsfm/util/errors.h"

namespace loopsfm {

void SequentialWavesOptions::Check() const {
  LOOPSFM_REQUIRE_OPTION(min_window >= 1, "sequential minimum window must be at least 1, got {}",
                         min_window);
  LOOPSFM_REQUIRE_OPTION(max_consecutive_failures >= 1,
                         "sequential window needs at least 1 failure to stop, got {}",
                         max_consecutive_failures);
  LOOPSFM_REQUIRE_OPTION(max_quadratic_step >= 0, "largest quadratic step must not be negative, got {}",
                         max_quadratic_step);
  LOOPSFM_REQUIRE_OPTION(max_quadratic_failures >= 1,
                         "quadratic steps need at least 1 failure to stop, got {}",
                         max_quadratic_failures);
}

namespace {

bool IsPowerOfTwo(int d) { return d > 0 && (d & (d - 1)) == 0; }

struct FrameState {
  bool linear_open = true;
  int linear_failures = 0;  // consecutive
  bool quadratic_open = true;
  int quadratic_failures = 0;  // consecutive
};

}  // namespace

SequentialWavesReport RunSequentialWaves(
    const std::vector<image_t>& ordered_ids, const SequentialPairingOptions& window,
    const SequentialWavesOptions& options,
    const VerifyPairsFn& verify, IndexPairSet* tried, IndexPairSet* verified,
    IndexPairSet* covered) {
  window.Check();
  options.Check();
  const int n = static_cast<int>(ordered_ids.size());
  LOOPSFM_CHECK(tried->NumFrames() == n && verified->NumFrames() == n);
  if (covered != nullptr) *covered = IndexPairSet(n);
  auto window_of = [&](int i) {
    return i < window.num_initial_frames ? window.initial_overlap : window.overlap;
  };
  const int largest_window = std::max(window.overlap, window.num_initial_frames > 0
                                                          ? window.initial_overlap
                                                          : window.overlap);
  const int last_distance = std::max(largest_window, options.max_quadratic_step);

  SequentialWavesReport report;
  std::vector<FrameState> state(n);
  for (int d = 1; d < n && d <= last_distance; ++d) {
    std::vector<int> from;
    std::vector<bool> quadratic;
    for (int i = 0; i + d < n; ++i) {
      FrameState& s = state[i];
      const bool linear = d <= window_of(i);
      if (linear ? !s.linear_open
                 : !(s.quadratic_open && IsPowerOfTwo(d) && d <= options.max_quadratic_step)) {
        continue;
      }
      from.push_back(i);
      quadratic.push_back(!linear);
    }
    if (from.empty()) continue;
    std::vector<ImagePair> wave;
    std::vector<size_t> wave_index;  // position in `from` of each pair sent to verify
    for (size_t k = 0; k < from.size(); ++k) {
      if (!tried->Contains(from[k], from[k] + d)) {
        wave.emplace_back(ordered_ids[from[k]], ordered_ids[from[k] + d]);
        wave_index.push_back(k);
      }
    }
    if (!wave.empty()) {
      const std::vector<bool> ok = verify(wave);
      LOOPSFM_CHECK(ok.size() == wave.size());
      for (size_t m = 0; m < wave.size(); ++m) {
        const int i = from[wave_index[m]], j = i + d;
        tried->Insert(i, j);
        if (ok[m]) verified->Insert(i, j);
        ++report.num_tried;
        report.num_verified += ok[m];
        if (quadratic[wave_index[m]]) {
          ++report.num_quadratic_tried;
          report.num_quadratic_verified += ok[m];
        }
      }
    }
    for (size_t k = 0; k < from.size(); ++k) {
      const int i = from[k];
      if (covered != nullptr) covered->Insert(i, i + d);
      FrameState& s = state[i];
      const bool ok = verified->Contains(i, i + d);
      if (quadratic[k]) {
        s.quadratic_failures = ok ? 0 : s.quadratic_failures + 1;
        if (s.quadratic_failures >= options.max_quadratic_failures) s.quadratic_open = false;
      } else {
        s.linear_failures = ok ? 0 : s.linear_failures + 1;
        if (s.linear_failures >= options.max_consecutive_failures && d >= options.min_window) {
          s.linear_open = false;
        }
      }
    }
  }
  return report;
}

}  // namespace loopsfm
