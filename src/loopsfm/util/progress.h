#pragma once
// Progress of a long stage. On a terminal (stderr is a tty) it draws a bar that
// redraws in place; otherwise it writes one status line every few seconds, so logs
// of CI or batch runs stay short. Thread-safe: workers call Advance() concurrently.

#include <atomic>
#include <cstddef>
#include <mutex>
#include <string>

#include "loopsfm/util/timer.h"

namespace loopsfm {

class Progress {
 public:
  // total == 0 means "unknown" (only the count and rate are shown).
  Progress(std::string stage, size_t total, bool enabled = true);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void Advance(size_t n = 1);
  // Draws the final state and a newline. Called by the destructor if not called before.
  void Finish();
  size_t Count() const { return count_.load(); }

 private:
  void Draw(bool final_line);

  std::string stage_;
  size_t total_;
  bool enabled_;
  bool tty_;
  std::atomic<size_t> count_{0};
  std::mutex mutex_;
  Timer timer_;
  double last_draw_ = -1e9;
  bool finished_ = false;
};

}  // namespace loopsfm
