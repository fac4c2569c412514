#include "core/synth_habits.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/synth_tuning.hpp"

namespace gearpulse {
namespace {

constexpr double kRollKnown = 3.0;  // s of rolling declutched seen before its idle counts (rolling_idle)
constexpr double kMinShifts = 3.0;  // shifts seen before the learned shift points are trusted
constexpr double kMinRevsSd = 0.1;  // in ln(freq): no gear is confined to a band narrower than +-10 %
// Samples a prior on a gear's revs is worth (load_gear_revs, lugged_band): a young model's few samples of
// a gear move its band only part of the way from the prior.
constexpr double kRevsPriorSamples = 20.0;
// Belief in the filter's most probable mode under GPS for a habit to be learned from it: GPS tells the
// gears apart (speed over revs) except in the moments of a shift, when the belief is split between them.
constexpr double kSureMode = 0.8;
// The edge of the lugging band (lugged()): its logistic falls from 0.95 to 0.05 over 2 ln(19) / 3 = 2 of the
// band's spreads, and the band's top lies at least far enough above the idle that the logistic reaches 0.95
// there, where the idle lugs any gear wholly.
constexpr double kLuggedSteepness = 3.0;
constexpr double kIdleLugged = 2.9444389791664403 / kLuggedSteepness;  // ln(19) / 3

// Running mean and variance with a bounded memory (in samples).
void accumulate(double x, double& mean, double& var, double& count, double memory) noexcept {
  count = std::min(count + 1.0, memory);
  const double k = 1.0 / count;
  const double d = x - mean;
  mean += k * d;
  var += k * (d * d * (1.0 - k) - var);
}

}  // namespace

void SynthHabits::load_engine(const ModelExtras& extras, const SynthTuning& tuning) noexcept {
  warm_idle_ = std::numeric_limits<double>::quiet_NaN();
  const double f = extras.idle_freq, sd = extras.idle_sd;
  idle_readable_ = !(std::isfinite(f) && f > 0.0 && f < tuning.reading_floor);
  if (std::isfinite(f) && f > 0.0) {
    warm_idle_ = f;
    if (idle_count_ <= 0.0 && std::isfinite(sd) && sd >= 0.0) {
      constexpr double kPriorSamples = 5.0;  // GPS standing overrules the prior within seconds
      idle_mean_ = f;
      idle_var_ = sd * sd;
      idle_count_ = kPriorSamples;
    }
  }
  // The rolling idle the fit saw, until GPS shows this car rolling (a prior worth a few samples, as the
  // idle's).
  if (const double rolling = extras.rolling_idle;
      roll_time_ <= 0.0 && std::isfinite(rolling) && rolling > 0.0) {
    constexpr double kPriorSamples = 5.0;
    roll_mean_ = rolling;
    roll_count_ = kPriorSamples;
    roll_time_ = kRollKnown;
  }
  // How hard this driver slowed declutched at idle in the fit's logs, until GPS shows it in this drive: worth
  // the seconds the fit saw, up to idle_braking_prior, so that the drive's own fixes soon outweigh it.
  const double a = extras.idle_braking_accel, seconds = extras.idle_braking_seconds;
  if (idle_coast_count_ <= 0.0 && tuning.idle_braking_prior > 0.0 && std::isfinite(a) &&
      std::isfinite(seconds) && seconds > 0.0) {
    idle_coast_mean_ = idle_braking::clip(a);
    idle_coast_count_ = std::min(seconds, tuning.idle_braking_prior);
  }
}

void SynthHabits::load_gear_revs(const ModelExtras& extras, const GearNumbers& model_gear,
                                 int gears) noexcept {
  revs_mean_.fill(0.0);
  revs_sd_.fill(0.0);
  revs_count_.fill(0.0);
  if (!extras.has_revs) return;
  // Each gear's revs are shrunk toward those of all gears by a prior worth kRevsPriorSamples samples: a
  // gear seen on a few samples (a short log, a first gear) says little, and one seen on none says what the
  // driver's revs say at large, rather than leaving the gears that were seen to outscore it.
  GearArray mean{}, var{}, count{};
  double total = 0.0, pooled_mean = 0.0;
  for (int j = 1; j <= gears; ++j) {
    if (model_gear[j] == 0) continue;  // a gear seen under GPS: the driver's revs at large (below)
    const ModelExtras::GearRevs& r = extras.revs[static_cast<std::size_t>(model_gear[j] - 1)];
    const double m = r.mean_log, sd = r.sd_log, n = r.samples;
    if (!std::isfinite(m) || !std::isfinite(sd) || sd < 0.0 || !std::isfinite(n) || !(n > 0.0)) continue;
    mean[j] = m;
    var[j] = sd * sd;
    count[j] = std::min(n, 1e9);
    total += count[j];
    pooled_mean += count[j] * m;
  }
  if (!(total > 0.0)) return;
  pooled_mean /= total;
  double pooled_var = 0.0;
  for (int j = 1; j <= gears; ++j)
    pooled_var += count[j] * (var[j] + (mean[j] - pooled_mean) * (mean[j] - pooled_mean));
  pooled_var /= total;
  for (int j = 1; j <= gears; ++j) {
    const double n = count[j];
    revs_mean_[j] = (n * mean[j] + kRevsPriorSamples * pooled_mean) / (n + kRevsPriorSamples);
    const double v = (n * var[j] + kRevsPriorSamples * pooled_var) / (n + kRevsPriorSamples);
    revs_sd_[j] = std::max(std::sqrt(v), kMinRevsSd);
    revs_count_[j] = n;
  }
}

// What GPS teaches about this engine and driver: the idle frequency (standing), the frequencies run at in
// gear and the deceleration declutched (moving).
void SynthHabits::learn(double t, double dt, double gps, double freq, bool gps_new, int mode, bool in_gear,
                        double belief, bool at_idle, const SynthTuning& tuning) noexcept {
  const bool was_moving = last_gps_ > 5.0 * tuning.stationary_speed;
  // Declutched is known from the revs: with the frequency lost every gear fades and the clutch holds the
  // belief whatever the car does, and a cruise seen so taught a deceleration of zero (after which a car
  // that lost GPS too was carried on at its last speed for good). Measured between fixes (a fix repeated at
  // the steps between them shows no change of speed) at least idle_braking::kMinGap apart: over less, the
  // change of speed is mostly the receiver's noise, and clipped unevenly above it taught a braking no car
  // did. A 1 Hz receiver's every fix is measured from the one before; a 5 or 10 Hz receiver's fixes closer
  // than that to the fix measured from wait (the next measurement spans them): measured fix to fix, its
  // 0.1 s steps never made an idle braking, and each counted as a whole 1 Hz measurement in the memory.
  if (gps_new) {
    const double fix_dt = t - from_t_;
    if (from_gps_ < 0.0 || fix_dt >= idle_braking::kMinGap) {
      if (from_gps_ >= 0.0 && was_moving && mode == 0 && belief > 0.8 && std::isfinite(freq) && freq > 0.0) {
        constexpr double kCoastMemory = 100.0;  // measurements
        const double a = idle_braking::clip((gps - from_gps_) / fix_dt);
        coast_count_ = std::min(coast_count_ + 1.0, kCoastMemory);
        coast_mean_ += (a - coast_mean_) / coast_count_;
        // At idle, each counting for the share of a second it covers (idle_coast_count_ is in seconds).
        if (at_idle) {
          const double w = idle_braking::weight(fix_dt);
          idle_coast_count_ = std::min(idle_coast_count_ + w, kCoastMemory);
          idle_coast_mean_ += w * (a - idle_coast_mean_) / idle_coast_count_;
        }
      }
      from_gps_ = gps;
      from_t_ = t;
    }
    last_gps_ = gps;
  }
  if (!std::isfinite(freq) || freq <= 0.0) {
    roll_span_ = -1.0;
    return;
  }
  const auto add = [&](double& mean, double& var, double& count, double memory) {
    accumulate(freq, mean, var, count, memory / std::max(dt, 0.1));
  };
  constexpr double kIdleMemory = 60.0;    // s
  constexpr double kDriveMemory = 600.0;  // s
  // Declutched on the move the engine idles too; a reading there at or below the idle learned so far
  // follows a warming engine down when the car no longer stops (a cold start's high idle otherwise stays,
  // and a car coasting at warm idle looks in gear).
  const bool idling_moving = tuning.idle_on_move > 0.0 && was_moving && mode == 0 && belief > kSureMode &&
                             idle_count_ > 0.0 && freq < idle_mean_ + idle_sd();
  // Rolling declutched above the standing idle (gear_model.hpp's rolling_idle rule, as the fit applies it
  // to a log): revs that no gear explains, flat while GPS shows the car slowing, are the rolling idle. Not a
  // shift's revs (they move), nor a slipping clutch's (the car gains speed, or creeps).
  using namespace rolling_idle;
  const bool roll_candidate = gps > kMinSpeed && was_moving && mode == 0 && belief > kSureMode &&
                              idle_count_ > 0.0 && freq >= idle_mean_ + idle_sd() &&
                              freq < kCeiling * idle_mean_;
  if (!roll_candidate) {
    roll_span_ = -1.0;
  } else if (roll_span_ < 0.0 || std::abs(freq - roll_freq_) > kFlat * roll_freq_) {
    roll_span_ = 0.0;
    roll_freq_ = freq;
    roll_speed_ = gps;
  } else {
    roll_span_ += dt;
    if (roll_span_ >= kSpan && gps < roll_speed_ - tuning.stationary_speed) {
      double var = 0.0;  // the spread is the idle's
      add(roll_mean_, var, roll_count_, kIdleMemory);
      roll_time_ += dt;
    }
  }
  if (gps < tuning.stationary_speed || idling_moving) {
    // A warming engine's idle only falls: a reading below the idle learned so far is followed sooner. No
    // reading is the idle of an engine idling below the readings' floor (SynthTuning::reading_floor).
    constexpr double kIdleFallMemory = 15.0;  // s
    if (idle_readable_)
      add(idle_mean_, idle_var_, idle_count_, freq < idle_mean_ ? kIdleFallMemory : kIdleMemory);
  } else if (in_gear && belief > kSureMode && gps > 10.0 * tuning.stationary_speed) {
    add(drive_mean_, drive_var_, drive_count_, kDriveMemory);
  }
}

void SynthHabits::learn_shift(int gear, double belief, double freq) noexcept {
  constexpr double kShiftMemory = 50.0;  // shifts
  if (gear == 0 || belief < kSureMode || !std::isfinite(freq)) return;
  if (sure_gear_ > 0 && gear == sure_gear_ + 1) {
    accumulate(sure_gear_freq_, up_mean_, up_var_, up_count_, kShiftMemory);
    accumulate(sure_gear_freq_, gear_up_mean_[sure_gear_], gear_up_var_[sure_gear_],
               gear_up_count_[sure_gear_], kShiftMemory);
  } else if (sure_gear_ > 0 && gear == sure_gear_ - 1) {
    accumulate(sure_gear_freq_, down_mean_, down_var_, down_count_, kShiftMemory);
    accumulate(sure_gear_freq_, gear_down_mean_[sure_gear_], gear_down_var_[sure_gear_],
               gear_down_count_[sure_gear_], kShiftMemory);
  }
  sure_gear_ = gear;
  sure_gear_freq_ = freq;
}

void SynthHabits::learn_pulled_shift(int mode, double belief, bool in_gear, bool pulling, bool rolling,
                                     double dt, double max_declutch) noexcept {
  if (!rolling) {
    forget_pulled_shift();  // a stop, not a shift
    return;
  }
  if (!in_gear) {
    // Declutched (the clutch or a move-off) after the pulling gear: the shift is on, as long as a shift's.
    if (pulled_gear_ > 0 && mode == 0 && pulled_declutch_ >= 0.0) {
      pulled_left_ = true;
      pulled_declutch_ += dt;
      if (pulled_declutch_ > max_declutch) pulled_declutch_ = -1.0;
    }
    return;
  }
  if (belief < kSureMode) return;
  if (pulled_gear_ > 0 && (mode != pulled_gear_ || pulled_left_) && pulled_declutch_ >= 0.0) {
    const PulledOutcome outcome = mode == pulled_gear_ + 1 ? kUpOne : mode == pulled_gear_ ? kSame : kOther;
    const double keep = 1.0 - 1.0 / kPulledShiftMemory;
    for (double& c : pulled_count_)
      c *= keep;
    pulled_count_[outcome] += 1.0;
  }
  pulled_gear_ = pulling ? mode : 0;
  pulled_declutch_ = 0.0;
  pulled_left_ = false;
}

// The same gears keep what was learned of them (their shift revs) under their new numbers.
void SynthHabits::renumber_gears(const GearNumbers& to, int old_gears) noexcept {
  for (GearArray* a : {&gear_up_mean_, &gear_up_var_, &gear_up_count_, &gear_down_mean_, &gear_down_var_,
                       &gear_down_count_}) {
    const GearArray old = *a;
    a->fill(0.0);
    for (int i = 1; i <= old_gears; ++i)
      if (to[i] > 0) (*a)[to[i]] = old[i];
  }
  sure_gear_ = sure_gear_ > 0 && sure_gear_ <= old_gears ? to[sure_gear_] : 0;
  if (pulled_gear_ > 0 && pulled_gear_ <= old_gears && to[pulled_gear_] > 0)
    pulled_gear_ = to[pulled_gear_];
  else
    forget_pulled_shift();  // the gear left is not in the new ladder
}

// Shift revs learned per gear belong to the old ladder.
void SynthHabits::forget_gear_shifts() noexcept {
  for (GearArray* a :
       {&gear_up_mean_, &gear_up_var_, &gear_up_count_, &gear_down_mean_, &gear_down_var_, &gear_down_count_})
    a->fill(0.0);
  forget_pulled_shift();
}

double SynthHabits::idle_freq() const noexcept {
  return idle_count_ > 0.0 ? idle_mean_ : std::numeric_limits<double>::quiet_NaN();
}

// Spread of the idle frequency learned (bounded: idle_spread).
double SynthHabits::idle_sd() const noexcept {
  return idle_spread(idle_mean_, std::sqrt(idle_var_));
}

// The idle of the engine while the car rolls declutched: many engines are held above their standing idle
// there (a throttle kicker, an idle-up against stalling), with revs that stay flat while the car slows.
// Learned under GPS (see learn()); the standing idle until seen for kRollKnown seconds.
double SynthHabits::rolling_idle(const SynthTuning& tuning) const noexcept {
  return roll_time_ >= kRollKnown && tuning.rolling_idle > 0.0 ? std::max(idle_mean_, roll_mean_)
                                                               : idle_mean_;
}

bool SynthHabits::at_idle(double freq, const SynthTuning& tuning) const noexcept {
  return std::isfinite(freq) && idle_count_ > 0.0 &&
         freq < rolling_idle(tuning) + idle_braking::kBandSds * idle_sd();
}

// The warm idle is the lower of the idle learned and the fit's.
bool SynthHabits::lacks_first_gear(double lowest_theta, const SynthTuning& tuning) const noexcept {
  return idle_speed(lowest_theta) > tuning.first_gear_idle_speed;  // false while NaN
}

double SynthHabits::idle_speed(double theta) const noexcept {
  double idle = std::isfinite(warm_idle_) ? warm_idle_ : std::numeric_limits<double>::infinity();
  if (idle_count_ > 0.0) idle = std::min(idle, idle_mean_);
  return std::isfinite(idle) ? theta * idle : std::numeric_limits<double>::quiet_NaN();
}

// Declutched, nothing drives the car: whatever GPS taught (a gear mistaken for the clutch while
// accelerating), it does not gain speed on its own. What GPS taught counts against the generic
// deceleration by how much it has seen: a few fixes at a steady speed in a declutch do not make a car
// that rolls on for good once the revs and GPS are both lost.
double SynthHabits::coast_accel(bool at_idle, const SynthTuning& tuning) const noexcept {
  constexpr double kCoastPrior = 10.0;  // fixes
  double mean = std::min(
      (coast_count_ * coast_mean_ + kCoastPrior * tuning.coast_accel) / (coast_count_ + kCoastPrior), 0.0);
  // With the engine at idle the clutch is not out for a shift (the free revs of a shift fall from one
  // gear's line toward the next's, or are blipped): the driver rolls or brakes to a stop, and how hard is
  // his habit. The car slows at the deceleration GPS showed in that state, shrunk toward the one
  // declutched at large by a prior worth a few fixes.
  if (at_idle && tuning.idle_braking > 0.0) {
    constexpr double kIdleCoastPrior = 3.0;  // s of fixes
    mean = std::min((idle_coast_count_ * idle_coast_mean_ + kIdleCoastPrior * mean) /
                        (idle_coast_count_ + kIdleCoastPrior),
                    0.0);
  }
  return mean;
}

// Scores this step's frequency in each gear by how usual it is there for this driver, against how usual it
// is in gears at large: ln(p(f | gear) / sum_k alpha_k p(f | k)), bounded (0 for every gear when the model
// records no revs). In steady driving every gear explains the revs equally well; what
// tells them apart is that this driver runs third at 1500-2200 rpm and fourth at 1800-2600.
void SynthHabits::score_revs(double freq, const GearArray& weight, int gears, const SynthTuning& tuning,
                             GearArray& out) const noexcept {
  out.fill(0.0);
  if (!std::isfinite(freq) || freq <= 0.0 || tuning.revs_habit <= 0.0) return;
  const double x = std::log(freq);
  GearArray density{};
  double total = 0.0, weights = 0.0;
  for (int j = 1; j <= gears; ++j) {
    if (revs_sd_[j] <= 0.0) continue;
    const double z = (x - revs_mean_[j]) / revs_sd_[j];
    density[j] = std::exp(-0.5 * z * z) / revs_sd_[j];
    total += weight[j] * density[j];
    weights += weight[j];
  }
  if (!(total > 0.0)) return;
  constexpr double kMaxHabit = 3.0;  // no single reading rules a gear in or out
  for (int j = 1; j <= gears; ++j) {
    if (revs_sd_[j] <= 0.0) continue;
    const double ratio = density[j] * weights / total;
    out[j] = ratio > 0.0 ? std::clamp(std::log(ratio), -kMaxHabit, kMaxHabit) : -kMaxHabit;
  }
}

// Where `freq` sits in the band of revs this driver runs `gear` at (the model's `extra.revs`), in its sds of
// ln(freq); the band must be known (revs_sd_ > 0) and freq positive.
double SynthHabits::revs_z(int gear, double freq) const noexcept {
  return (std::log(freq) - revs_mean_[gear]) / revs_sd_[gear];
}

// How much likelier a shift from `from` to `to` at `freq` is for bringing the revs nearer the band this
// driver runs the new gear in than they are to the band of the old one (the model's revs per gear): a
// driver shifts up as the revs pass his habit and lands where he usually drives the next gear, and does
// not shift down into revs he never runs that gear at. 1 when the model does not know both gears' revs.
double SynthHabits::shift_comfort(int from, int to, double theta_from, double theta_to, double freq,
                                  const SynthTuning& tuning) const noexcept {
  if (tuning.shift_comfort <= 0.0 || !std::isfinite(freq) || freq <= 0.0 || revs_sd_[from] <= 0.0 ||
      revs_sd_[to] <= 0.0)
    return 1.0;
  const double now = revs_z(from, freq);
  const double after = revs_z(to, freq * theta_from / theta_to);
  constexpr double kMaxLog = 3.0;
  return std::exp(std::clamp(0.5 * tuning.shift_comfort * (now * now - after * after), -kMaxLog, kMaxLog));
}

// How much more likely an upshift (and less likely a downshift) is at this engine frequency than at the
// frequency this driver usually runs at in gear: drivers shift up as revs rise and down as they sag.
double SynthHabits::shift_urge(double freq) const noexcept {
  constexpr double kMinDriveSamples = 20.0;
  if (!std::isfinite(freq) || drive_count_ < kMinDriveSamples) return 1.0;
  const double sd = std::max(std::sqrt(drive_var_), 0.05 * drive_mean_);
  return std::exp(std::clamp((freq - drive_mean_) / sd, -3.0, 3.0));
}

// Lugging is driving a gear at revs too low for it: the engine judders, and a driver declutches or shifts
// down instead (except creeping in first gear, which SpeedSynthesizer weighs apart). Where that begins is
// this driver's: below the revs he holds his gears at. Per gear above first, the low end of the band the
// fit saw him run it in (extra.revs, as load_gear_revs shrinks it: kLuggedSds of its spread in ln(freq)
// below its mean, the revs he runs it below 5 % of the time); the band's top is the lowest of these, with
// the spread of the gear it comes from. First gear is left out: its revs reach down to the idle, since a car
// creeps in it. The engine at its idle lugs any gear, so the top is never less than the idle (rolling, as
// the car may be) by kIdleLugged spreads. Without the fit's revs (an older model) that floor is the band.
SynthHabits::LuggedBand SynthHabits::lugged_band(int gears, const SynthTuning& tuning) const noexcept {
  constexpr double kLuggedSds = 1.645;  // the 5 % quantile of a normal band
  const double idle = std::log(rolling_idle(tuning));
  LuggedBand band{std::numeric_limits<double>::infinity(), kMinRevsSd};
  for (int j = std::clamp(gears, 1, 2); j <= gears; ++j) {
    if (!(revs_count_[j] > 0.0)) continue;  // a gear the fit did not see says nothing of how it is held
    const double sd = revs_sd_[j];
    const double low = revs_mean_[j] - kLuggedSds * sd;
    // A gear the fit saw on few samples (a young model's) moves the top from the idle's floor only as far
    // as its samples outweigh the prior.
    const double floor = idle + kIdleLugged * sd;
    const double seen = revs_count_[j] / (revs_count_[j] + kRevsPriorSamples);
    const double top = floor + seen * (std::max(low, floor) - floor);
    if (top < band.top) band = {top, sd};
  }
  if (!std::isfinite(band.top)) band = {idle + kIdleLugged * kMinRevsSd, kMinRevsSd};
  return band;
}

// A logistic in ln(freq) around the band's top, kLuggedSteepness per spread of the band; wholly lugged at or
// below the idle.
double SynthHabits::lugged(double freq, int gears, const SynthTuning& tuning) const noexcept {
  if (!std::isfinite(freq) || freq <= 0.0 || idle_count_ <= 0.0) return 0.0;
  if (freq <= rolling_idle(tuning)) return 1.0;
  const LuggedBand band = lugged_band(gears, tuning);
  const double x = kLuggedSteepness * (std::log(freq) - band.top) / band.sd;
  return 1.0 / (1.0 + std::exp(std::clamp(x, -50.0, 50.0)));
}

// Hazard multipliers of shifting up or down at this frequency, from the frequencies at which this driver
// was seen shifting (drivers shift up as revs reach their habit, down as revs sag to theirs). Before any
// shift was seen, the frequency usually run in gear stands in for both.
double SynthHabits::upshift_factor(int gear, double freq, const SynthTuning& tuning) const noexcept {
  if (!std::isfinite(freq)) return 1.0;
  // This gear's own upshift revs once seen a few times (a driver shifts out of first lower than out of
  // fourth), else those of all gears.
  const bool own = tuning.gear_shift_points > 0.0 && gear_up_count_[gear] >= kMinShifts;
  const double mean = own ? gear_up_mean_[gear] : up_mean_, var = own ? gear_up_var_[gear] : up_var_;
  if (!own && up_count_ < kMinShifts) return shift_urge(freq);
  const double sd = std::max(std::sqrt(var), 0.08 * mean);
  return std::exp(std::clamp((freq - mean) / sd, -1.5, 3.0));
}

// Before shifts down were seen, between readings further apart than the tracker's hops, the revs the model
// records for this gear (`extra.revs`) stand in: a driver shifts down out of fifth when the revs sag below
// where he runs fifth, not below where he runs the car at large. Against the latter, a fifth gear held at
// 29 Hz in a steady cruise (the Etios, long1 from 681 s; its driver runs fifth at 24 Hz, sd 0.45 in
// ln(freq)) lost the belief to a fourth gear 11 km/h low for the rest of the outage. Not for shifts up:
// a gear's band says where it is run, not where it is left upward (first gear's is a creep's, and a car
// creeping in first at high revs in a queue was read in second, 10 km/h fast); nor at the tracker's hops,
// where it moved the simulated figures both ways and the daemon's path stays as measured.
double SynthHabits::downshift_factor(int gear, double freq, bool long_step,
                                     const SynthTuning& tuning) const noexcept {
  if (!std::isfinite(freq)) return 1.0;
  const bool own = tuning.gear_shift_points > 0.0 && gear_down_count_[gear] >= kMinShifts;
  const double mean = own ? gear_down_mean_[gear] : down_mean_, var = own ? gear_down_var_[gear] : down_var_;
  if (!own && down_count_ < kMinShifts) {
    if (long_step && tuning.downshift_band > 0.0 && revs_sd_[gear] > 0.0 && freq > 0.0)
      return std::exp(std::clamp(-revs_z(gear, freq), -3.0, 3.0));
    return 1.0 / shift_urge(freq);
  }
  const double sd = std::max(std::sqrt(var), 0.08 * mean);
  return std::exp(std::clamp(-(freq - mean) / sd, -1.5, 3.0));
}

}  // namespace gearpulse
