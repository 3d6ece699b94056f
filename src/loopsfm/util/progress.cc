#include "loopsfm/util/progress.h"

#include <unistd.h>

#include <cstdio>

namespace loopsfm {

Progress::Progress(std::string stage, size_t total, bool enabled)
    : stage_(std::move(stage)), total_(total), enabled_(enabled), tty_(isatty(STDERR_FILENO)) {}

Progress::~Progress() { Finish(); }

void Progress::Advance(size_t n) {
  count_ += n;
  if (!enabled_) return;
  const double interval = tty_ ? 0.1 : 5.0;
  std::unique_lock lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || finished_) return;
  if (timer_.ElapsedSeconds() - last_draw_ >= interval) Draw(false);
}

void Progress::Finish() {
  std::lock_guard lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (enabled_) Draw(true);
}

void Progress::Draw(bool final_line) {
  last_draw_ = timer_.ElapsedSeconds();
  const size_t count = count_.load();
  const double rate = last_draw_ > 0 ? count / last_draw_ : 0.0;
  if (tty_) {
    constexpr int kWidth = 30;
    std::string bar;
    if (total_ > 0) {
      const int filled = static_cast<int>(kWidth * std::min<double>(1.0, double(count) / total_));
      bar = "[" + std::string(filled, '#') + std::string(kWidth - filled, '.') + "] ";
    }
    std::fprintf(stderr, "\r%-10s %s%zu%s%s  %.1f/s  %.1fs%s", stage_.c_str(), bar.c_str(), count,
                 total_ > 0 ? "/" : "", total_ > 0 ? std::to_string(total_).c_str() : "", rate,
                 last_draw_, final_line ? "\n" : "");
  } else {
    std::fprintf(stderr, "%s: %zu%s%s done, %.1f/s, %.1fs%s\n", stage_.c_str(), count,
                 total_ > 0 ? " of " : "", total_ > 0 ? std::to_string(total_).c_str() : "", rate,
                 last_draw_, final_line ? " (finished)" : "");
  }
  std::fflush(stderr);
}

}  // namespace loopsfm
