#pragma once
// Wall-clock timer for stage reports (never used to make decisions).

#include <chrono>

namespace loopsfm {

class Timer {
 public:
  Timer() : start_(Clock::now()) {}
  void Restart() { start_ = Clock::now(); }
  double ElapsedSeconds() const {
    return std::chrono::duration<double>(Clock::now() - start_).count();
  }
  double ElapsedMillis() const { return ElapsedSeconds() * 1e3; }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point start_;
};

// Peak resident memory of this process in bytes (VmHWM), or 0 where unknown.
long long PeakResidentBytes();

}  // namespace loopsfm
