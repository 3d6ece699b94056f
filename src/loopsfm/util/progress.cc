#include "loopsfm/util/progress.h"

#include <unistd.h>

#include <cstdio>
#include <exception>

#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// Seconds between calls of RunHooks::progress (and polls of stop_requested) per stage.
constexpr double kHookInterval = 0.2;

}  // namespace

void ThrowIfStopRequested(const RunHooks* hooks, const std::string& where) {
  if (hooks && hooks->stop_requested && hooks->stop_requested()) {
    throw Cancelled(fmt::format("asked to stop during {}; what was stored stays, and running "
                                "the same command again goes on from there",
                                where));
  }
}

Progress::Progress(std::string stage, size_t total, bool enabled, const RunHooks* hooks)
    : stage_(std::move(stage)),
      total_(total),
      enabled_(enabled),
      hooks_(hooks),
      tty_(isatty(STDERR_FILENO)),
      uncaught_at_start_(std::uncaught_exceptions()) {}

Progress::~Progress() { Finish(std::uncaught_exceptions() > uncaught_at_start_); }

void Progress::Advance(size_t n) {
  count_ += n;
  Show();
}

void Progress::Set(size_t count) {
  count_ = count;
  Show();
}

void Progress::Show() {
  if (!enabled_ && !hooks_) return;
  std::unique_lock lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || finished_) return;
  const double now = timer_.ElapsedSeconds();
  if (enabled_ && now - last_draw_ >= (tty_ ? 0.1 : 5.0)) Draw(false);
  if (hooks_ && now - last_hook_ >= kHookInterval) {
    last_hook_ = now;
    if (hooks_->progress) hooks_->progress(stage_, count_.load(), total_);
    lock.unlock();
    ThrowIfStopRequested(hooks_, stage_);
  }
}

void Progress::Finish() { Finish(false); }

void Progress::Finish(bool stopped) {
  std::lock_guard lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (enabled_) Draw(true, stopped);
  if (stopped) return;
  if (hooks_ && hooks_->progress) hooks_->progress(stage_, count_.load(), total_);
}

void Progress::Draw(bool final_line, bool stopped) {
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
                 last_draw_, final_line ? (stopped ? " (stopped)" : " (finished)") : "");
  }
  std::fflush(stderr);
}

}  // namespace loopsfm
