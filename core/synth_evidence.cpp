// The scores of the synthesis's mode filter (SpeedSynthesizer, core/speed_synth.hpp): how well each mode
// explains the engine frequency (a gear by its track's innovation, declutched by idle or free revs, moving
// off by revs held above idle), and the chance of a gear at lugged revs.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "core/speed_synth.hpp"
#include "core/synth_constants.hpp"

namespace gearpulse {

using namespace synth;

// The modes are scored by how well each explains the frequency in units of its own spread (a gear: the
// standardised innovation of its track), not by a density: a density of the frequency favours whichever
// gear turns a given uncertainty of speed into the narrowest spread of revs, and self-consistent histories
// in other gears would gain on the true one with every steady sample. A frequency that no gear explains
// within kFreeRevs sigmas is as well explained by an engine running free.
namespace {
constexpr double kFreeRevs = 3.0;
constexpr double kFreeRevsCost = 0.5 * kFreeRevs * kFreeRevs;  // a second of free revs, log-units
constexpr double kLaunchRevs = 2.5;  // moving off: likelier than free revs with the car at rest
}  // namespace

double SpeedSynthesizer::freq_sigma(double freq) const noexcept {
  return std::max(sigma_s_, tuning_.min_freq_rel * freq);
}

// Score of the frequency declutched at `speed`: the engine falls to idle (a spike, as the paper's g() has one
// at standstill, section 3.1) or runs free anywhere in its range.
double SpeedSynthesizer::log_declutched(double freq, double speed) const noexcept {
  const double free = -kFreeRevsCost;
  if (!habits_.idle_known()) return free;
  // Revs running free are a shift in progress; with the car at rest they are rare (a blip), and revs held
  // above idle there mean moving off.
  constexpr double kStandingFree = 0.05;
  const double free_share = speed > kMovingOffSpeed ? 1.0 - tuning_.idle_weight : kStandingFree;
  // A warming engine's idle only falls: revs between the idle learned last (perhaps while the engine was
  // still cold) and the warm idle the fit saw are the idle now.
  // A young fit's idle may be a cold engine's, as the idle learned then: the warm one lies up to
  // cold_idle_ratio below it.
  const double warm = std::isfinite(habits_.warm_idle()) && tuning_.warm_floor > 0.0
                          ? std::min(habits_.warm_idle(), habits_.idle_mean())
                          : habits_.idle_mean();
  const double floor = young_idle_ && tuning_.cold_idle_ratio > 1.0
                           ? std::min(warm, habits_.idle_mean() / tuning_.cold_idle_ratio)
                           : warm;
  // Rolling, many engines are held above their standing idle (the rolling idle, learned under GPS).
  const double top = speed > kMovingOffSpeed ? rolling_idle() : habits_.idle_mean();
  const double z = freq > top ? (freq - top) / idle_sd() : freq < floor ? (floor - freq) / idle_sd() : 0.0;
  return std::log((1.0 - free_share) * std::exp(-0.5 * z * z) + free_share * std::exp(free));
}

// Score of the frequency read inside the declutch of an upshift from `gear` that began within this step,
// the car's speed predicted by `x`: the engine, let go, falls from the gear's line toward the next gear's
// revs (where the clutch coming back in will hold it) or on toward idle, so the reading lies between; half
// of such readings are taken to lie above the next gear's revs and half anywhere down to idle, uniformly
// (a density of the revs, in the units of a gear's score: the gear's own spread at its line scores 0).
// Scored as free revs, such a reading cost the clutch as much as a reading that no mode explains, and a gear
// took it: at 1 Hz a launch's declutch from first to second caught at 117 Hz (the paper's BMW 520i, 23 km/h)
// was second gear at 30 km/h, third gear took the next reading, and the filter stayed a gear high, 12-13 km/h
// fast, for the rest of the outage. Not on the gear's line or within one of its sigmas of it: the free
// engine leaves the line within a moment of the clutch going out, and a reading there is the gear's.
double SpeedSynthesizer::log_declutching(int gear, double freq, const Track& x) const noexcept {
  constexpr double kNextShare = 0.5;
  const double v = std::max(x.v, 0.0);
  const double line = v / theta_[gear];
  const double h = 1.0 / theta_[gear];
  const double sf = std::sqrt(h * h * x.pvv + freq_sigma(freq) * freq_sigma(freq));
  const double idle = habits_.idle_known() ? rolling_idle() : 0.0;
  const auto between = [&](double floor) {
    const double lo = floor - 2.0 * sf, hi = line - sf;
    return hi > lo && freq >= lo && freq <= hi ? 1.0 / (hi - lo) : 0.0;
  };
  const double density = gear < gears_ ? kNextShare * between(std::max(v / theta_[gear + 1], idle)) +
                                             (1.0 - kNextShare) * between(idle)
                                       : between(idle);
  return density > 0.0 ? std::log(std::sqrt(2.0 * std::numbers::pi) * sf * density)
                       : -std::numeric_limits<double>::infinity();
}

// Slipping the clutch is how a car moves off, not how it drives: the score of moving off at `speed`
// (revs set aside) falls as the car gains speed, below that of a shift in progress, so a moving car's
// free revs are not taken for a launch. 0 at walking pace.
double SpeedSynthesizer::launch_plausibility(double speed) const noexcept {
  const double slow = -0.5 * kLaunchRevs * kLaunchRevs;
  const double fast = -kFreeRevsCost + std::log(1.0 - tuning_.idle_weight) - 1.0;
  const double share = std::clamp((speed - kMovingOffSpeed) / (3.0 * kMovingOffSpeed), 0.0, 1.0);
  return tuning_.launch_fade > 0.0 && !lacks_first_gear() ? share * (fast - slow) : 0.0;
}

// Score of the frequency while the clutch slips moving off at `speed`: revs held above idle.
double SpeedSynthesizer::log_launch(double freq, double speed) const noexcept {
  const double base = -0.5 * kLaunchRevs * kLaunchRevs + launch_plausibility(speed);
  if (!habits_.idle_known()) return base;
  const double above = 1.0 / (1.0 + std::exp(-(freq - habits_.idle_mean() - 2.0 * idle_sd()) / idle_sd()));
  return base + std::log(std::max(above, 0.05));
}

// Relative chance of driving in `gear` with this step's frequency: below the revs this driver holds his gears
// at (SynthHabits::lugged) he declutches rather than lug the engine, except when creeping in first gear. A
// gear seen under GPS only at such revs (creep_) may be a creep on a slipping clutch, whose ratio holds only
// while the revs are held there: above them it is as unlikely as a gear driven lugged. Carried as a gear
// up the revs, a queue's creep at a third of first gear's ratio took the move-off after it, and the filter
// climbed a ladder of such ratios at half the car's speed (`compact-4/s2`, jam, from 302 s, OBD 1 s).
double SpeedSynthesizer::lugging(int gear) const noexcept {
  const double floor = gear == 1 ? tuning_.lugging_first : tuning_.lugging_other;
  if (creep_[gear] > 0.0) return tuning_.lugging_other + (1.0 - tuning_.lugging_other) * lugged_;
  return 1.0 - (1.0 - floor) * lugged_;
}

// Log-score of the frequency under `mode` given the track (updated in place by a gear's reading).
double SpeedSynthesizer::log_evidence(Track& x, int mode, double freq, double weight,
                                      bool short_step) const noexcept {
  if (!std::isfinite(freq)) {
    // A reading lost for kTrackerGap or less (one row of a 1 Hz log) says nothing of the mode. Lost for
    // longer, a gear fades.
    const double lost = lost_for_ > kTrackerGap + 1e-6 ? tuning_.lost_gear_cost : 0.0;
    if (is_gear(mode)) return -weight * lost;
    // Moving off is told by the revs: without them it is as unsupported as a gear, and at speed not a
    // launch at all, so its acceleration cannot carry the speed away while the frequency is lost.
    return mode == launch_mode() ? weight * (-lost + launch_plausibility(x.v)) : 0.0;
  }
  // Declutched, moving off and lugging are states: their scores count per second of being in them.
  if (mode == 0) {
    // Rolling, revs climbing fast cost the clutch up to as much again as free revs (climb_, filter_step).
    const double climb = x.v > kMovingOffSpeed ? tuning_.climb_cost * climb_ * kFreeRevsCost : 0.0;
    return weight * (log_declutched(freq, x.v) - climb);
  }
  if (mode == launch_mode()) {
    // The clutch slips: the engine turns faster than the wheels in first gear, so the car is no faster
    // than theta_1 x freq. A track beyond that is pulled back to it, for the squared excess (an event).
    const double ceiling = theta_[1] * freq;
    double cost = 0.0;
    if (x.v > ceiling) {
      const double sd = std::sqrt(x.pvv) + theta_[1] * freq_sigma(freq);
      const double z = (x.v - ceiling) / sd;
      cost = jump_cost(z * z);
      x.v = ceiling;
      x.a = std::min(x.a, 0.0);
    }
    return weight * log_launch(freq, x.v) - cost;
  }
  // In gear: freq = v / theta (eq. (3)); a Kalman update on h = 1 / theta.
  const double h = 1.0 / theta_[mode];
  const double sf = freq_sigma(freq);
  // The gear's theta is known to its standard error: the reading of a gear seen in few fixes is trusted less.
  const double se = freq * theta_se_[mode] / theta_[mode];
  const double r = sf * sf + se * se;
  const double s = h * h * x.pvv + r;
  const double innovation = freq - h * x.v;
  const double kv = x.pvv * h / s, ka = x.pva * h / s;
  x.v += kv * innovation;
  x.a += ka * innovation;
  const double pvv = x.pvv - kv * h * x.pvv, pva = x.pva - kv * h * x.pva, paa = x.paa - ka * h * x.pva;
  x.pvv = pvv;
  x.pva = pva;
  x.paa = paa;
  keep_covariance(x);
  // A reading its gear explains within the dead zone costs in proportion to the time it covers (weight),
  // however often it comes; a jump the track cannot follow costs its squared excess once (the track then
  // follows): an event, counted once at any sample rate. A gear just entered is scored as one held.
  const double z2 = innovation * innovation / s;
  // A departure beyond the dead zone upward at a short step is a manoeuvre (a clutch biting, a hard launch
  // in first gear): the acceleration is open again, so the next readings find the new one and a ramp is
  // paid for once, as a jump is, not at every reading. Not downward: a car's deceleration in gear builds
  // up over the moment its brakes take, while revs falling at once at a steady speed are the clutch going
  // out, which the declutched mode explains; reopened, a gear's history read a shift's falling revs as
  // braking at no more than one jump's cost and outlived the shift one gear low. A longer step's
  // prediction already carries that uncertainty (a fifth of the stationary spread or more from a tenth of
  // accel_time on).
  if (short_step && tuning_.jump_reopen > 0.0 && z2 > kDeadZone * kDeadZone && innovation > 0.0)
    x.paa = std::max(x.paa, tuning_.accel_sigma * tuning_.accel_sigma);
  return -jump_cost(z2) - 0.5 * weight * std::min(z2, kDeadZone * kDeadZone) +
         weight * (std::log(lugging(mode)) + tuning_.revs_habit * revs_habit_[mode]);
}

}  // namespace gearpulse
