#include "daemon/state_saver.hpp"

#include <algorithm>
#include <utility>

namespace gearpulse::daemon {

StateSaver::StateSaver(Writes writes, Seconds save_interval, Seconds journal_interval)
    : writes_(std::move(writes)), journal_interval_(journal_interval), save_interval_(save_interval) {}

StateSaver::~StateSaver() {
  stop();
}

void StateSaver::start() {
  {
    std::lock_guard lock(mutex_);
    stop_ = false;
  }
  thread_ = std::thread([this] { run(); });
}

void StateSaver::stop() noexcept {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void StateSaver::set_save_interval(Seconds interval) noexcept {
  {
    std::lock_guard lock(mutex_);
    save_interval_ = interval;
  }
  wake_.notify_all();
}

StateSaver::Seconds StateSaver::busy_for() const noexcept {
  std::lock_guard lock(mutex_);
  return writing_since_ ? Seconds(Clock::now() - *writing_since_) : Seconds(0.0);
}

void StateSaver::run() noexcept {
  const auto after = [](Clock::time_point t, Seconds s) {
    return t + std::chrono::duration_cast<Clock::duration>(s);
  };
  auto last_save = Clock::now();
  auto last_journal = last_save;
  std::unique_lock lock(mutex_);
  while (!stop_) {
    const auto save_due = after(last_save, save_interval_);
    const auto due = std::min(save_due, after(last_journal, journal_interval_));
    if (wake_.wait_until(lock, due, [&] { return stop_ || after(last_save, save_interval_) != save_due; }))
      continue;  // stopping, or the save interval changed: the loop's test or a new deadline
    const auto now = Clock::now();
    const bool save = now >= save_due;
    writing_since_ = now;
    lock.unlock();
    // The writes say their own faults (StateDirectory) and do not throw.
    if (save) {
      if (writes_.unsaved() && !writes_.save()) writes_.journal();
    } else {
      writes_.journal();
    }
    lock.lock();
    writing_since_.reset();
    last_journal = now;
    if (save) last_save = now;
  }
}

}  // namespace gearpulse::daemon
