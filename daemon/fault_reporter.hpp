#pragma once
// The live chain's faults in the journal: a fault is said when it happens, then at most once a minute
// with how often it happened meanwhile, and its end once. Thread-safe (LogLimiter) for report() and
// clear(); audio() belongs to the tracker thread.
#include <chrono>
#include <string>

#include <spdlog/spdlog.h>

#include "daemon/log_limiter.hpp"
#include "drivers/alsa_capture.hpp"

namespace gearpulse::daemon {

class FaultReporter {
 public:
  explicit FaultReporter(std::string audio_device) : device_(std::move(audio_device)) {}

  // A fault under `key` (one key per kind of fault): logged now, or counted if it was logged less than a
  // minute ago.
  void report(const std::string& key, spdlog::level::level_enum level, const std::string& text);
  // The fault under `key` is over: `text` is logged, and its next occurrence is logged at once.
  void clear(const std::string& key, const std::string& text);
  // The open capture's faults: a lost device (reopened by the capture thread), audio that freezes and
  // audio that stalls, each said when it starts and when it ends; a device that comes and goes (a loose
  // connector) at most once a minute.
  void audio(const AlsaCaptureStats& stats, std::chrono::steady_clock::time_point at);

 private:
  std::string device_;
  LogLimiter limiter_;
  StateFault lost_;
  StateFault frozen_;
  StateFault stalled_;
};

}  // namespace gearpulse::daemon
