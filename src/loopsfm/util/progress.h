#pragma once
// Progress of a long stage. On a terminal (stderr is a tty) it draws a bar that
// redraws in place; otherwise it writes one status line every few seconds, so logs
// of CI or batch runs stay short. Thread-safe: workers call Advance() concurrently.

#include <atomic>
#include <cstddef>
#include <functional>
#include <mutex>
#include <string>

#include "loopsfm/util/timer.h"

namespace loopsfm {

// How a caller of a run (the Python module, the program on Ctrl-C) follows its progress and
// asks it to stop. Every Progress of the run reports to it; both members are optional.
struct RunHooks {
  // Called with the stage, the units done and their total (0: unknown): a few times a second
  // while the stage advances, and once at its end; from whichever thread advanced it.
  std::function<void(const std::string& stage, size_t done, size_t total)> progress;
  // Polled as often; true stops the run with Cancelled (loopsfm/util/errors.h) from the
  // thread that advanced. What the run has stored stays, and a rerun resumes from it.
  std::function<bool()> stop_requested;
};

// Throws Cancelled when `hooks` asks the run to stop; for the points between stages.
void ThrowIfStopRequested(const RunHooks* hooks, const std::string& where);

class Progress {
 public:
  // total == 0 means "unknown" (only the count and rate are shown). `hooks` (may be null)
  // must outlive the Progress.
  Progress(std::string stage, size_t total, bool enabled = true,
           const RunHooks* hooks = nullptr);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Throws Cancelled when the hooks ask the run to stop.
  void Advance(size_t n = 1);
  // Sets the count (for stages that know it, not its steps); throws as Advance.
  void Set(size_t count);
  // Draws the final state and a newline. Called by the destructor if not called before; there,
  // while an exception (a stop, an error) unwinds the stage, the line says it stopped.
  void Finish();
  size_t Count() const { return count_.load(); }

 private:
  // Draws and calls the hooks when it is time; throws Cancelled when they ask to stop.
  void Show();
  // `stopped`: the final line says the stage stopped instead of finishing.
  void Draw(bool final_line, bool stopped = false);
  void Finish(bool stopped);

  std::string stage_;
  size_t total_;
  bool enabled_;
  const RunHooks* hooks_;
  bool tty_;
  std::atomic<size_t> count_{0};
  std::mutex mutex_;
  Timer timer_;
  double last_draw_ = -1e9;
  double last_hook_ = -1e9;
  bool finished_ = false;
  // Exceptions in flight when the stage began (std::uncaught_exceptions).
  int uncaught_at_start_ = 0;
};

}  // namespace loopsfm
