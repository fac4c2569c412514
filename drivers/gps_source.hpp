#pragma once
// Where GPS speed comes from: gpsd in the daemon, a scripted source in tests. (Not to be confused with
// core's SpeedSource, which says where a synthesized speed came from.)
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>

namespace gearpulse {

// One GPS report as received. Time base: CLOCK_MONOTONIC ns of reception (subtract a configured latency
// to get the fix's age); fix_time is the receiver's UTC time, for logs and ordering only.
struct GpsReport {
  std::int64_t rx_ns = 0;                                      // CLOCK_MONOTONIC when received
  double speed = std::numeric_limits<double>::quiet_NaN();     // m/s over ground, NaN = unknown
  double eps = std::numeric_limits<double>::quiet_NaN();       // m/s, speed error estimate, NaN = unknown
  int mode = 0;                                                // 0 unknown, 1 no fix, 2 2D, 3 3D
  double fix_time = std::numeric_limits<double>::quiet_NaN();  // UTC s since the epoch, NaN = unknown

  // A usable speed: a 2D/3D fix with a finite speed (freshness is judged separately).
  [[nodiscard]] bool usable() const noexcept { return mode >= 2 && speed == speed; }
};

class GpsSource {
 public:
  using Callback = std::function<void(const GpsReport&)>;
  virtual ~GpsSource() = default;
  // The newest report, if any arrived yet.
  [[nodiscard]] virtual std::optional<GpsReport> latest() const = 0;
  // The newest report if it is usable and was received no longer ago than the no-fix timeout (its speed
  // and its freshness judged on that one report).
  [[nodiscard]] virtual std::optional<GpsReport> fresh(std::int64_t now_ns) const = 0;
  [[nodiscard]] bool has_gps(std::int64_t now_ns) const { return fresh(now_ns).has_value(); }
};

}  // namespace gearpulse
