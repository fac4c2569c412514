#pragma once
// GPS speeds no car reaches, or reaches that fast: a receiver's glitch (a multipath spike, a bad epoch)
// that would otherwise drive the pulse train (300 m/s for five epochs is 1.5 km of pulses) and teach the
// estimator. A speed is refused above max_speed, or when it differs from the last accepted one by more
// than max_accel allows over the time between them (plus the receiver's noise); judged on max_speed
// alone when the last accepted speed is older than reference_s (a long outage: no reference).
// Pure and allocation-free; one per GPS source.
#include <cmath>
#include <cstdint>

namespace gearpulse {

class GpsSpeedGate {
 public:
  struct Limits {
    double max_speed = 90.0;   // m/s (324 km/h)
    double max_accel = 12.0;   // m/s^2, beyond any car's braking or launch
    double noise = 1.0;        // m/s, a receiver's epoch-to-epoch noise, always allowed
    double reference_s = 5.0;  // s, age beyond which the last accepted speed is no reference
  };
  enum class Verdict : std::uint8_t { kAccepted, kTooFast, kTooSudden };

  GpsSpeedGate() = default;
  explicit GpsSpeedGate(Limits limits) noexcept : limits_(limits) {}

  // `fix_s`: the fix's own time (UTC s, NaN when unknown); `rx_s`: when it was received (monotonic s);
  // `speed`: m/s, finite and >= 0. The time between two fixes is the fixes' own when both have one and
  // it runs forward (a batch delivered late is not a fast change), else the receive times' (a receiver
  // whose clock stepped back is still judged: a spike behind such a step is a spike).
  Verdict check(double fix_s, double rx_s, double speed) noexcept {
    if (!(speed <= limits_.max_speed)) return Verdict::kTooFast;
    const bool timed = std::isfinite(fix_s) && std::isfinite(last_fix_) && fix_s >= last_fix_;
    const double dt = timed ? fix_s - last_fix_ : rx_s - last_rx_;
    if (has_last_ && dt >= 0.0 && dt <= limits_.reference_s &&
        std::abs(speed - last_speed_) > limits_.max_accel * dt + limits_.noise)
      return Verdict::kTooSudden;
    has_last_ = true;
    last_fix_ = fix_s;
    last_rx_ = rx_s;
    last_speed_ = speed;
    return Verdict::kAccepted;
  }
  void reset() noexcept { has_last_ = false; }

 private:
  Limits limits_{};
  bool has_last_ = false;
  double last_fix_ = 0.0;
  double last_rx_ = 0.0;
  double last_speed_ = 0.0;
};

}  // namespace gearpulse
