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

// OBD loggers poll speed and rpm in turn, about every 2 s, and write each value again on every row until
// its next poll: a held value is at most this old.
inline constexpr double kHeldSpan = 3.0;  // s: a polling round and a half

// A sample of a log with no speed whose frequency repeats exactly that of `stepped`, the last sample the
// synthesis was stepped with, at most kHeldSpan later: the rpm an OBD logger holds between its polls and
// writes again on rows that refresh only the speed, which a GPS outage has taken out. It brings no reading
// at all, so the offline synthesis answers it with its last output, as it does a row repeating both held
// values (sample_io.hpp), instead of stepping the filter with revs as of an earlier instant: a held value
// reads as revs held flat and then jumping, and each copy counts as a reading of its own. Later than
// kHeldSpan the same value is a reading again (an engine switched off reads 0 for good). A tracker's or a
// GPS logger's frequencies do not repeat exactly.
[[nodiscard]] inline bool repeats_held_freq(const Sample& stepped, const Sample& s) noexcept {
  return !s.has_speed() && s.has_freq() && s.freq == stepped.freq && s.t - stepped.t <= kHeldSpan;
}

}  // namespace gearpulse
