#pragma once
// One training/replay sample: time, GPS speed and engine-related frequency (paper eqs. (1)-(2)).
#include <cmath>
#include <limits>

namespace gearpulse {

inline constexpr double kMissing = std::numeric_limits<double>::quiet_NaN();

struct Sample {
  double t = 0.0;           // s (offline: the CSV's t; daemon: CLOCK_MONOTONIC seconds)
  double speed = kMissing;  // m/s, NaN = no GPS fix
  double freq = kMissing;   // Hz of the tracked engine component, NaN = not tracked

  [[nodiscard]] bool has_speed() const noexcept { return std::isfinite(speed); }
  [[nodiscard]] bool has_freq() const noexcept { return std::isfinite(freq); }
};

}  // namespace gearpulse
