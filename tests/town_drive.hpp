#pragma once
// The hatch the synthesis's tests drive (its ladder, idle and model), and a town drive whose fixes can be
// made late, for the tests of how late GPS speed is (SpeedLag) and of the stages that feed the synthesis
// its fixes.
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "core/gear_model.hpp"

namespace gearpulse::test {

inline constexpr double kIdle = 13.3;                                           // Hz
inline const std::vector<double> kHatch = {0.125, 0.225, 0.347, 0.471, 0.574};  // (m/s)/Hz

// A model of the ladder `theta` ((m/s)/Hz, each ratio times `scale`), its gears equally used.
inline std::shared_ptr<const GearModel> model_of(const std::vector<double>& theta, double scale = 1.0) {
  auto m = std::make_shared<GearModel>();
  for (double t : theta)
    m->gears.push_back({t * scale, 1.0 / static_cast<double>(theta.size()), 0.0});
  m->sigma_speed = 0.1;
  m->sigma_freq = 0.3;
  m->outlier_weight = 0.1;
  return m;
}

// The hatch's model, its fit having found the speeds `speed_lag` s late against the revs.
inline std::shared_ptr<const GearModel> hatch_model(double speed_lag = 0.0) {
  auto m = std::make_shared<GearModel>(*model_of(kHatch));
  if (speed_lag != 0.0) m->extra["speed_lag"] = speed_lag;
  return m;
}

// A town drive of cycles of 37 s: standing 8 s at idle, moving off in first gear (the clutch slipping below
// 25 Hz) at 2 m/s^2 for 3 s, 0.4 s declutched, second at 1.5 m/s^2 for 4 s, 0.4 s declutched, third at
// 1 m/s^2 for 5 s, 6 s cruising, braking in third at 2 m/s^2 for 4 s, then declutched to a stop.
struct Truth {
  double speed, freq;
};
class TownDrive {
 public:
  static constexpr double kCycle = 37.0;
  static constexpr double kSecondGear = 11.4;  // s into a cycle: second gear bites
  static constexpr double kCruiseEnd = 27.8;   // s into a cycle: the car starts braking

  Truth at(double t) const {
    const double c = std::fmod(t, kCycle);
    struct Phase {
      double until, accel;
      int gear;
    };
    static constexpr Phase kPhases[] = {{8.0, 0.0, 0},  {11.0, 2.0, 1},  {11.4, 0.0, 0},
                                        {15.4, 1.5, 2}, {15.8, 0.0, 0},  {20.8, 1.0, 3},
                                        {26.8, 0.0, 3}, {30.8, -2.0, 3}, {kCycle, -2.0, 0}};
    double v = 0.0, from = 0.0, last_line = kIdle, since_declutch = 0.0;
    for (const Phase& p : kPhases) {
      const double end = std::min(c, p.until);
      v = std::max(0.0, v + p.accel * (end - from));
      if (p.gear > 0) last_line = v / kHatch[static_cast<std::size_t>(p.gear - 1)];
      if (c <= p.until) {
        if (p.gear == 1) return {v, std::max(v / kHatch[0], 25.0)};
        if (p.gear > 0) return {v, v / kHatch[static_cast<std::size_t>(p.gear - 1)]};
        since_declutch = c - from;
        // Declutched the engine falls from the gear's line toward idle.
        return {v, kIdle + (last_line - kIdle) * std::exp(-since_declutch / 0.3)};
      }
      from = p.until;
    }
    return {v, kIdle};
  }
};

// Walks `cycles` of a TownDrive at hops of `hop` s, calling at_hop(t, freq, fix) at each: `fix` is the speed
// `late` s before t once a second from t = late on (a fix `late` s late), NaN at the other hops.
template <class AtHop>
void walk_town_drive(double cycles, double hop, double late, AtHop&& at_hop) {
  const TownDrive drive;
  const int per_fix = static_cast<int>(std::lround(1.0 / hop));
  for (int k = 0; k * hop < cycles * TownDrive::kCycle; ++k) {
    const double t = k * hop;
    const bool fix = k % per_fix == 0 && t >= late;
    at_hop(t, drive.at(t).freq, fix ? drive.at(t - late).speed : std::numeric_limits<double>::quiet_NaN());
  }
}

// A TownDrive at the daemon's feed (the revs every 0.1 s, a fix once a second and 0.5 s late, held 1.5 s
// after GPS is lost), GPS lost at `lost` s and back at `back`: the outage's distance error, %, of
// `step(t, gps, freq, fresh)` (the speed output; gps NaN once lost).
template <class Step>
double town_drive_outage_error(double lost, double back, Step&& step) {
  constexpr double kLate = 0.5;  // s
  const TownDrive drive;
  double fix = std::numeric_limits<double>::quiet_NaN(), fix_t = -10.0, synthesized = 0.0, driven = 0.0;
  for (int k = 0; k * 0.1 < back; ++k) {
    const double t = k * 0.1;
    const Truth now = drive.at(t);
    bool fresh = false;
    if (k % 10 == 0 && t < lost) fix = drive.at(std::max(t - kLate, 0.0)).speed, fix_t = t, fresh = true;
    const double gps = t < lost || t - fix_t < 1.5 ? fix : std::numeric_limits<double>::quiet_NaN();
    const double speed = step(t, gps, now.freq, fresh);
    if (t >= lost) synthesized += speed * 0.1, driven += now.speed * 0.1;
  }
  return 100.0 * (synthesized - driven) / driven;
}

// The same over the first move-off, GPS lost in first gear 2 s after moving off.
template <class Step>
double first_launch_outage_error(Step&& step) {
  return town_drive_outage_error(TownDrive::kSecondGear - 1.0, TownDrive::kCruiseEnd, step);
}

}  // namespace gearpulse::test
