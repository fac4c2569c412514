#pragma once
// GPS reports as the gpsd client publishes them, and which of them carry a fix not measured before.
#include <cmath>
#include <cstdint>
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

// Tells whether a report carries a measurement not given before. gpsd may report one fix more than once
// (a receiver's epoch arrives as several sentences, each a report), and a caller that polls the newest
// report at every step of its own sees it again until the next arrives; the synthesis measures each fix
// once. A fix is known by its receiver time and speed (a receiver's clock may stand still while the car
// moves); a report without a receiver time, by when it was received.
class FixNovelty {
 public:
  // Whether `report` is new against the last one given; it becomes the last one.
  [[nodiscard]] bool is_new(const GpsReport& report) noexcept {
    const bool fresh = !seen_ || (std::isfinite(report.fix_time)
                                      ? report.fix_time != fix_time_ || !same_speed(report.speed, speed_)
                                      : report.rx_ns != rx_ns_);
    seen_ = true;
    fix_time_ = report.fix_time;
    speed_ = report.speed;
    rx_ns_ = report.rx_ns;
    return fresh;
  }

 private:
  static bool same_speed(double a, double b) noexcept { return a == b || (std::isnan(a) && std::isnan(b)); }

  bool seen_ = false;
  double fix_time_ = 0.0;
  double speed_ = 0.0;
  std::int64_t rx_ns_ = 0;
};

}  // namespace gearpulse
