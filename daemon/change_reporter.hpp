#pragma once
// The journal's account of the pipeline: one line per change of state between two snapshots (GPS lost
// or back, the speed's source leaving GPS or coming back to it, an output without a reader), and
// repeated faults at most once a minute, so a log read at 2 a.m. tells what happened and when. Used by
// the main thread only.
#include <chrono>
#include <cstdint>

#include "daemon/config.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/pipeline.hpp"

namespace gearpulse::daemon {

class ChangeReporter {
 public:
  explicit ChangeReporter(const Config& config) : config_(config) {}
  // `at`: when `now` was taken (the states said at most once a minute are timed by it).
  void log(const PipelineSnapshot& before, const PipelineSnapshot& now,
           std::chrono::steady_clock::time_point at = std::chrono::steady_clock::now());

 private:
  const Config& config_;  // the device names the lines give
  LogLimiter limiter_;
  StateFault no_reader_;                 // the pulse output has no reader (a PTY nobody holds open)
  StateFault no_fix_;                    // gpsd is connected but gives no usable fix
  StateFault write_errors_;              // writes to the pulse output fail
  StateFault away_from_gps_;             // the speed does not come from GPS
  bool gps_source_seen_ = false;         // the speed has come from GPS
  bool gps_connected_ = false;           // as the last line said
  bool gps_fixed_ = false;               // a fix was said once
  bool gps_lost_ = false;                // the connection to gpsd was lost since the last fix said
  std::uint64_t gps_failures_seen_ = 0;  // GPS connection failures looked at
};

}  // namespace gearpulse::daemon
