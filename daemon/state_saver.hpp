#pragma once
// The periodic writes of the training store, on a thread of their own. Every `save_interval` the store is
// saved if it holds something its file does not (a failed save journals instead, so the pairs are kept
// however short the interval); between saves the new pairs are journaled every `journal_interval`. A
// write that stalls (an fsync on a failing SD card may take tens of seconds) then holds up neither the
// main loop, which alone feeds the systemd watchdog and says the pipeline's faults, nor a reload or a
// status reply; how long the write in progress has run is for status and the log to say.
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>

namespace gearpulse::daemon {

class StateSaver {
 public:
  using Seconds = std::chrono::duration<double>;
  struct Writes {
    std::function<bool()> unsaved;  // the store holds pairs (or a clear) its file does not
    std::function<bool()> save;     // false when the save failed
    std::function<void()> journal;  // appends the pairs since the last save or append
  };

  StateSaver(Writes writes, Seconds save_interval, Seconds journal_interval);
  ~StateSaver();
  StateSaver(const StateSaver&) = delete;
  StateSaver& operator=(const StateSaver&) = delete;

  void start();
  // Ends the thread after the write in progress, if any (what is left unsaved is the caller's to save).
  void stop() noexcept;
  // Takes effect at once: a wait under way ends at the new interval.
  void set_save_interval(Seconds interval) noexcept;
  // How long the write in progress has run, zero when none is.
  [[nodiscard]] Seconds busy_for() const noexcept;

 private:
  using Clock = std::chrono::steady_clock;
  void run() noexcept;

  Writes writes_;
  Seconds journal_interval_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  Seconds save_interval_;
  bool stop_ = false;
  std::optional<Clock::time_point> writing_since_;  // the write in progress began then
  std::thread thread_;
};

}  // namespace gearpulse::daemon
