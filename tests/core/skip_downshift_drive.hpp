#pragma once
// A drive both synthesizers are held to: braking in 4th from 85 to 40 km/h at 3.2 m/s^2, 0.4 s declutched,
// then 2nd gear (a skip) just as GPS is lost, 60 s in 2nd at 24-34 km/h.
#include <algorithm>
#include <cmath>
#include <span>
#include <utility>

#include "core/sample.hpp"

namespace gearpulse::test {

// Steps `synth` over the drive of a car whose gears are `theta` ((m/s)/Hz, 4th and 2nd used) idling at
// `idle` Hz: the daemon's feed (the frequency every 0.1 s, a 1 Hz fix held for 1.5 s after it came,
// measured once) or a log's (rows every second). Returns the outage distance's error, %.
template <class Synth>
double skip_downshift_outage(Synth& synth, std::span<const double> theta, double idle, bool daemon_feed) {
  constexpr double kBrake = 3.2, kFrom = 85.0 / 3.6, kTo = 40.0 / 3.6;
  constexpr double kBrakeStart = 60.0, kBrakeEnd = kBrakeStart + (kFrom - kTo) / kBrake;
  constexpr double kLost = kBrakeEnd + 0.4, kEnd = kLost + 60.0;
  const double fourth = theta[3], second = theta[1];
  const auto truth = [&](double t) -> std::pair<double, double> {  // speed, frequency
    if (t < kBrakeStart) return {kFrom, kFrom / fourth};
    if (t < kBrakeEnd) {
      const double v = kFrom - kBrake * (t - kBrakeStart);
      return {v, v / fourth};
    }
    if (t < kLost) {
      const double v = kTo - 0.3 * (t - kBrakeEnd);
      return {v, 0.5 * (v / fourth + idle)};
    }
    const double start = kTo - 0.3 * 0.4, cruise = (29.0 + 5.0 * std::sin((t - kLost) / 20.0 * 6.2832)) / 3.6;
    const double v = start + (cruise - start) * std::min(1.0, (t - kLost) / 5.0);
    return {v, v / second};
  };
  const double step = daemon_feed ? 0.1 : 1.0;
  double fix = kMissing, fix_t = -10.0, synthesized = 0.0, driven = 0.0;
  for (int k = 0; k * step < kEnd; ++k) {
    const double t = k * step;
    const auto [v, f] = truth(t);
    bool fresh = false;
    if (t < kLost && (!daemon_feed || k % 10 == 0)) fix = v, fix_t = t, fresh = true;
    const double held = daemon_feed ? 1.5 : 0.0;  // the daemon's GPS timeout
    const double gps = t < kLost || t - fix_t < held ? fix : kMissing;
    const auto o = synth.step(t, gps, f, fresh);
    if (t >= kLost) synthesized += o.speed * step, driven += v * step;
  }
  return 100.0 * (synthesized - driven) / driven;
}

}  // namespace gearpulse::test
