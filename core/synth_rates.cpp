// The mode changes of the synthesis's mode filter (SpeedSynthesizer, core/speed_synth.hpp): the rates per
// second at which a gear is left for the clutch or a neighbouring gear, the clutch for a gear or for moving
// off, and moving off for the gear the clutch bites in, as the probabilities of each over a step.
#include <algorithm>
#include <cmath>

#include "core/speed_synth.hpp"
#include "core/synth_constants.hpp"

namespace gearpulse {

using namespace synth;

namespace {

// Probability over dt of leaving a mode by a route of `rate` per second, out of `total_rate` per second of
// leaving it by any route.
double leave_by(double dt, double total_rate, double rate) noexcept {
  const double leave = total_rate > 0.0 ? 1.0 - std::exp(-total_rate * dt) : 0.0;
  return total_rate > 0.0 ? leave * rate / total_rate : 0.0;
}

}  // namespace

// Mode changes over dt out of mode `from`, as rates per second: a gear is left for the clutch or for a
// neighbouring gear (a quick shift between two samples; up more likely at high revs, down at low revs);
// the clutch is left for any gear in proportion to its use (for the gear above one it came from while that
// pulled, at the upshift share learned), or, standing, for moving off; moving off ends
// when the clutch bites in first (or second) gear.
void SpeedSynthesizer::transitions_from(int from, double dt, double freq, double speed, ModeArray& row,
                                        double& caught_share) const noexcept {
  row.fill(0.0);
  caught_share = 0.0;
  if (is_gear(from))
    gear_transitions(from, dt, freq, row, caught_share);
  else if (from == 0)
    clutch_transitions(dt, speed, row);
  else
    launch_transitions(dt, row);
}

// Out of gear `from` (the revs `freq`); `caught_share` as transitions_from.
void SpeedSynthesizer::gear_transitions(int from, double dt, double freq, ModeArray& row,
                                        double& caught_share) const noexcept {
  // A gear is left about as often as its share of use suggests (a first gear is left soon), for the
  // clutch or for a neighbour: up as the revs pass this driver's upshift point, down as they sag.
  constexpr double kToClutch = 0.5, kToNeighbour = 0.25;
  const double base = leave_rate_[from];
  const bool long_step = hop_ >= kShortStep * tuning_.accel_time;  // not the tracker's hops
  const double shift_base = base * kToNeighbour;
  double up = from < gears_ ? shift_base * habits_.upshift_factor(from, freq, tuning_) *
                                  shift_comfort(from, from + 1, freq)
                            : 0.0;
  // First gear is for moving off: the longer it has lasted, the likelier the upshift (a launch whose
  // upshift the revs did not show, between two slow readings, is not held in first gear for good). Not
  // while the revs stay near idle: creeping in a queue is done in first gear for minutes.
  if (from == 1 && tuning_.launch_gear_time > 0.0) {
    constexpr double kMaxLaunchUrge = 5.0;
    constexpr double kCreepRevs = 1.3, kPullingRevs = 1.8;  // x idle: creeping below, pulling above
    const double x = age_[1] / tuning_.launch_gear_time;
    double urge = std::min(x * x, kMaxLaunchUrge);
    if (habits_.idle_known() && std::isfinite(freq))
      urge *= std::clamp((freq / habits_.idle_mean() - kCreepRevs) / (kPullingRevs - kCreepRevs), 0.0, 1.0);
    up *= 1.0 + urge;
  }
  double down = from > 1 ? shift_base * habits_.downshift_factor(from, freq, long_step, tuning_) *
                               shift_comfort(from, from - 1, freq)
                         : 0.0;
  // Every shift passes through the clutch. Between readings further apart than the tracker's hops, a
  // reading may fall inside the declutch of a shift due at these revs, with revs that neither gear
  // explains: that chance is the declutch's share of the step, over and above the shift that the reading
  // finds done. Without it, a skip-shift from third to fifth caught at 30 Hz, its revs falling from
  // third's 43 at 54 km/h, was fifth gear's at 62 km/h (a jump beyond the dead zone costs less than free
  // revs and the leaving of a gear), and fourth gear's reading of the next one, 12 km/h low, later took
  // the belief back for most of the outage. At the tracker's short steps the declutch shows on several
  // readings and the clutch's own rate holds it (measured: counted there too, it cost the 10 Hz figures,
  // presets 2.23 -> 2.59 km/h p95).
  double clutch = base * kToClutch;
  const double caught = long_step ? up * std::min(1.0, tuning_.declutch_time / dt) : 0.0;
  clutch += caught;
  caught_share = clutch > 0.0 ? caught / clutch : 0.0;
  // Leaving a gear is never given a hazard beyond the cost of a second of free revs, which the clutch
  // pays for any reading: past that, staying in a gear whose line the revs keep following costs more per
  // second than the clutch explaining nothing. A hard launch revved out in first gear, far past this
  // driver's upshift revs and first gear's time, was lost to the clutch while the car still pulled, and
  // with it the speed (11 km/h in first gear at a true 27 in fourth, for half a minute).
  if (const double sum = clutch + up + down; sum > tuning_.leave_cap) {
    const double k = tuning_.leave_cap / sum;
    clutch *= k;
    up *= k;
    down *= k;
  }
  const double total = clutch + up + down;
  row[from] = std::exp(-total * dt);
  row[0] += leave_by(dt, total, clutch);
  const double skip = tuning_.skip_share;
  if (from < gears_) {
    const bool can_skip = from + 2 <= gears_;
    row[from + 1] += leave_by(dt, total, up * (can_skip ? 1.0 - skip : 1.0));
    if (can_skip) row[from + 2] += leave_by(dt, total, up * skip);
  }
  if (from > 1) {
    const bool can_skip = from - 2 >= 1;
    row[from - 1] += leave_by(dt, total, down * (can_skip ? 1.0 - skip : 1.0));
    if (can_skip) row[from - 2] += leave_by(dt, total, down * skip);
  }
}

// Out of the clutch at `speed`.
void SpeedSynthesizer::clutch_transitions(double dt, double speed, ModeArray& row) const noexcept {
  const int launch = launch_mode();
  // Standing, the clutch is let in by moving off; rolling, a gear is engaged; in between, either.
  const double rolling = std::clamp((speed - tuning_.stationary_speed) / kMovingOffSpeed, 0.0, 1.0);
  const double engage = tuning_.engage_rate * rolling;
  const double launch_rate = speed < kMovingOffSpeed ? tuning_.launch_rate : 0.0;
  const double total = engage + launch_rate;
  row[0] = std::exp(-total * dt);
  row[launch] += leave_by(dt, total, launch_rate);
  // A declutch after a pulling gear is most often an upshift: the share of the clutch's belief that came
  // from a gear while it pulled (pulled_, note_pulled) engages the gear above at the share of such
  // declutches this driver ended in the gear above under GPS; the rest of the engagement goes by use.
  const double up_share = tuning_.pulled_engage > 0.0 ? habits_.upshift_share() : 0.0;
  double above = 0.0;
  for (int g = 1; g < gears_; ++g)
    above += pulled_[g] * up_share;
  const double by_use = std::max(1.0 - above, 0.0);
  for (int j = 1; j <= gears_; ++j) {
    const double share = by_use * weight_[j] / (1.0 - weight_[0]) + (j > 1 ? pulled_[j - 1] * up_share : 0.0);
    row[j] += leave_by(dt, total, engage * share);
  }
  // Moving off and biting within the same step (a step may be longer than a launch): of the launches
  // begun at a uniform time inside dt, the share whose clutch has bitten by its end.
  const double bite = tuning_.bite_rate * dt;
  const double bitten = bite > 1e-6 ? 1.0 - (1.0 - std::exp(-bite)) / bite : 0.5 * bite;
  const double launched = row[launch];
  const double second = gears_ > 1 ? tuning_.launch_second : 0.0;
  row[launch] = launched * (1.0 - bitten);
  row[1] += launched * bitten * (1.0 - second);
  if (gears_ > 1) row[2] += launched * bitten * second;
}

// Out of moving off.
void SpeedSynthesizer::launch_transitions(double dt, ModeArray& row) const noexcept {
  const int launch = launch_mode();
  // Ends when the clutch bites. A driver who gives up is seen at rest again by the declutched mode's own
  // history (kept at rest meanwhile); a move-off handing its guessed speed to a declutched car would
  // not be.
  const double total = tuning_.bite_rate;
  row[launch] = std::exp(-total * dt);
  const double second = gears_ > 1 ? tuning_.launch_second : 0.0;
  row[1] += leave_by(dt, total, tuning_.bite_rate * (1.0 - second));
  if (gears_ > 1) row[2] += leave_by(dt, total, tuning_.bite_rate * second);
}

}  // namespace gearpulse
