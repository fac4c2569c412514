// One step of the synthesis's mode filter (SpeedSynthesizer, core/speed_synth.hpp): each mode's motion
// (predict), and every history from one mode into another predicted over the step, corrected by GPS and
// scored by the frequency, then summed per mode into its belief and track and pruned.
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/speed_synth.hpp"
#include "core/synth_constants.hpp"

namespace gearpulse {

using namespace synth;

namespace {

constexpr double kNegligible = 1e-2;   // belief, relative to the leading mode, worth a history of its own
constexpr double kStandingVar = 0.01;  // (m/s)^2: a car at rest is at rest
// Declutches up to this many declutch_time long count toward the upshift share after a pulling gear
// (learn_pulled_shift): by then the clutch's memory of the pull (note_pulled) has faded to e^-4.
constexpr double kPulledDeclutches = 4.0;
// Declutched, the engine runs free: its revs fall toward idle, or rise in a blip the driver gives (matching
// the revs for a downshift). Revs that climb by more than kFreeRise a second are an engine pulling the car.
constexpr double kFreeRise = 0.2;  // 1/s, relative; above the tracker's hop-to-hop jitter

}  // namespace

// Propagates a track over dt under the motion of mode `to`: the acceleration is an Ornstein-Uhlenbeck
// process around a mode's mean (0 in gear, the learned coasting deceleration declutched, a launch while
// moving off), the speed its integral; the covariance grows by the exact integrals of that process, so
// many short steps give the same uncertainty as one long one.
void SpeedSynthesizer::predict(Track& x, int to, double dt) const noexcept {
  double mean = 0.0, sigma = tuning_.accel_sigma;
  if (to == 0) {
    // Declutched, nothing drives the car: it rolls and brakes as this driver does (SynthHabits).
    mean = habits_.coast_accel(at_idle_, tuning_);
    // Rolling slowly declutched, a driver is braking to a stop: the last metres go at a firm deceleration.
    const double stopping =
        tuning_.stop_speed > 0.0 ? std::clamp(1.0 - x.v / tuning_.stop_speed, 0.0, 1.0) : 0.0;
    mean = std::min(mean, mean + stopping * (tuning_.stop_accel - mean));
    sigma = tuning_.coast_sigma;
  } else if (to == launch_mode()) {
    mean = tuning_.launch_accel;
    sigma = tuning_.launch_sigma;
  }
  const double tau = to == 0 ? tuning_.coast_time : tuning_.accel_time;
  const double u = dt / tau;
  const double phi = std::exp(-u);
  const double g = tau * (1.0 - phi);  // speed gained per unit of acceleration departure
  // Exact covariance of the integrated OU process; its small-u series where the closed form cancels.
  const double s2 = sigma * sigma;
  const double qvv = u < 1e-3 ? s2 * tau * tau * (2.0 / 3.0) * u * u * u
                              : s2 * tau * tau * (2.0 * u - 3.0 + 4.0 * phi - phi * phi);
  const double qva = s2 * tau * (1.0 - phi) * (1.0 - phi);
  const double qaa = s2 * (1.0 - phi * phi);
  const double v = x.v + mean * dt + (x.a - mean) * g;
  const double a = mean + (x.a - mean) * phi;
  const double pvv = x.pvv + 2.0 * g * x.pva + g * g * x.paa + qvv;
  const double pva = phi * (x.pva + g * x.paa) + qva;
  const double paa = phi * phi * x.paa + qaa;
  x = {v, a, pvv, pva, paa};
  keep_covariance(x);
  if (x.v <= 0.0 && to != launch_mode()) {
    // Rolled to a stop: at rest, not going backwards.
    x = {0.0, 0.0, kStandingVar, 0.0, x.paa};
  }
}

// The step's inputs as every history is scored on them (StepInput). A fix is the speed of `lag` s before this
// step (SpeedLag, from the fix's stamp), and each track is held to it less what the car gained since, as far
// as it was measured: over the steps before this one, the gain of the filter's own speed then (the revs of
// the gears it followed); within this step, the gain of a gear's line over the time it has been held. Not the
// track's predicted acceleration: a late fix measured against it teaches the track its own guess, and at rest
// any fix is explained by a braking no car does.
SpeedSynthesizer::StepInput SpeedSynthesizer::step_input(double dt, double gps, double freq, bool gps_new,
                                                         double gps_age) const noexcept {
  StepInput in;
  in.dt = dt;
  in.gps = gps;
  in.freq = freq;
  in.have_gps = std::isfinite(gps);
  in.measure_gps = in.have_gps && gps_new;  // a repeated fix is not measured again
  // Share of a second of evidence this step carries (states are scored per second, see log_evidence): one
  // reading's, the hop's (a step over a tracker gap has one reading too).
  in.weight = std::clamp(hop_ / tuning_.evidence_time, 0.0, 1.0);
  in.short_step = hop_ < kShortStep * tuning_.accel_time;  // the tracker's hops, not GPS or OBD rows
  // A fix's departure from the model (the lag's error times the acceleration, the receiver's own filter)
  // persists over the second the revs' departures do (evidence_time): fixes closer together than that are
  // one measurement shared among them, each with its variance widened by the share it holds. Counted between
  // the fixes' stamps, not the steps that take them (a 1 Hz fix taken at the next tracker hop is a second's).
  // A fix stamped with the one before it adds next to nothing (kLeastFixShare).
  constexpr double kLeastFixShare = 1e-3;
  const double since_fix = fix_stamp(gps_age) - fix_measured_t_;
  in.gps_var = sigma_v_ * sigma_v_ / std::clamp(since_fix / tuning_.evidence_time, kLeastFixShare, 1.0);
  in.lacks_first = lacks_first_gear();
  in.lag = fix_lag(gps_age);
  double in_step = std::min(in.lag, dt);
  if (in.measure_gps && in.lag > 0.0) {
    double then = 0.0, last = 0.0;
    if (in.lag > dt && speed_lag_.speed_at(t_ - in.lag, then) && speed_lag_.speed_at(t_ - dt, last))
      in.gained = last - then;
    else
      in_step = in.lag;
    for (int j = 1; j <= gears_ && std::isfinite(freq); ++j) {
      const double span = std::min(in_step, age_[j] + dt);
      double before = freq;
      if (speed_lag_.revs_at(t_ - span, before)) in.revs_gain[j] = freq - before;
    }
  }
  return in;
}

// What this step's revs say beside the modes' scores: how usual they are in each gear for this driver,
// whether the engine is at idle or lugged, and how fast they climb.
void SpeedSynthesizer::read_revs(const StepInput& in) noexcept {
  const double freq = in.freq;
  habits_.score_revs(freq, weight_, gears_, tuning_, revs_habit_);
  // The engine at idle: within the band of revs a braking to a stop or a roll declutched shows
  // (idle_braking).
  at_idle_ = habits_.at_idle(freq, tuning_);
  // An engine let go falls to idle within a shift's declutch (declutch_time), its revs slowed by its own
  // friction at about a constant rate: after dt about 1 - dt / declutch_time of its revs above the rolling
  // idle remain. Revs that fell further than that fell faster than an engine does, and by that much (the
  // share they overshot) the reading is off the engine's line (a lock of the tracker on another order, as
  // often at half the engine as anywhere) rather than a declutch (declutch_pull_spread). None at steps as
  // long as a declutch: an engine falls anywhere within them.
  fell_too_fast_ = 0.0;
  if (in.dt > 0.0 && habits_.idle_known() && std::isfinite(freq) && std::isfinite(prev_freq_) &&
      prev_freq_ > rolling_idle()) {
    const double left = std::clamp(1.0 - in.dt / std::max(tuning_.declutch_time, 1e-3), 0.0, 1.0);
    const double seen = std::max(freq - rolling_idle(), 0.0) / (prev_freq_ - rolling_idle());
    fell_too_fast_ = std::clamp(left - seen, 0.0, 1.0);
  }
  lugged_ = habits_.lugged(freq, gears_, tuning_);
  // How fast the revs climb, from kFreeRise (0) to twice it (1): only at the tracker's short steps, where
  // one reading to the next is shorter than a shift, so the climb is the engine's and not a shift's
  // between two readings. A driver who shifts every second or so otherwise had each gear outweigh the
  // clutch only a second after it bit, with the clutch's speed left behind as the car pulled; mixed in at
  // the next declutch, that speed made the gear below fit the revs (a random 6-speed in town, climbing to
  // 40 km/h in fifth, was read in second at 15).
  climb_ = 0.0;
  if (in.short_step && in.dt > 0.0 && std::isfinite(freq) && std::isfinite(prev_freq_) && prev_freq_ > 0.0) {
    const double rise = (freq - prev_freq_) / (prev_freq_ * in.dt);
    climb_ = std::clamp((rise - kFreeRise) / kFreeRise, 0.0, 1.0);
  }
}

// The track of mode `i` as it enters mode `j` at the start of the step, before its motion over it.
SpeedSynthesizer::Track SpeedSynthesizer::entering(int i, int j, bool moving_off,
                                                   bool have_gps) const noexcept {
  Track x = track_[i];
  // Moving off (into the launch mode, or through it into a gear within this step): the clutch slips
  // and the car gains speed at a launch acceleration.
  if (moving_off) x = {x.v, tuning_.launch_accel, x.pvv, 0.0, tuning_.launch_sigma * tuning_.launch_sigma};
  const double carried = x.a;  // the acceleration the history carried into the step
  // Declutching ends the engine's drive: the car no longer gains speed. Nor does a car declutched
  // all along once GPS is lost, whatever gain GPS showed it (a slipping clutch, revs no gear explains).
  if (j == 0 && (i != 0 || !have_gps)) x.a = std::min(x.a, 0.0);
  // The brakes are the driver's: once the clutch goes out, the deceleration may go on, ease or stop.
  if (j == 0 && i != 0) {
    const double spread = tuning_.declutch_brake_spread * x.a;
    x.paa = std::max(x.paa, spread * spread);
  }
  // A pulling gear's history sent to the clutch by revs that fell faster than an engine let go falls
  // (fell_too_fast_): by that share the reading was off the engine's line and the car pulls on, so the
  // clutch's history keeps that share of the pull, and as much again as its spread. Without it, a reading at
  // half the engine during a launch (first gear's revs at twice the idle put it on the idle band) took the
  // belief to a clutch that stopped gaining speed; first gear, entered again from that speed when the revs
  // returned to its line, paid a jump that grew with the pull, and the clutch held the rest of the outage
  // (`random-503/s1`, urban, from 840 s: 4.2 m/s against a true 5-7, -31.6 %).
  if (j == 0 && is_gear(i) && carried > 0.0 && tuning_.declutch_pull_spread > 0.0) {
    const double kept = tuning_.declutch_pull_spread * carried * fell_too_fast_;
    x.a = std::max(x.a, kept);
    x.paa = std::max(x.paa, kept * kept);
  }
  // A shift within the step: the engine's pull reaches the wheels through the new gear, as theta_i /
  // theta_j of the force at the same torque (eq. (3): theta is the speed per turn of the engine), so a
  // car that was pulling carries that share of its acceleration into the gear it enters; braking is the
  // brakes' and stays. Carried whole, a hard launch's pull in first gear made second gear's reading of
  // revs falling in the declutch (a car at 21 km/h read at 33) a jump the acceleration partly
  // explained, and at 1 Hz the filter climbed the ladder one gear high. A move-off's acceleration is
  // first gear's: moving off in second, the car gains speed theta_1 / theta_2 as fast (at 1 Hz a
  // launch read in second gained enough to fit second's reading of the revs, kept a history of its own
  // at 1.7 times the speed of a car creeping in first, and took the belief back 8 s later).
  const int pulling = moving_off || i == launch_mode() ? 1 : i;  // the gear whose pull x.a is
  if (tuning_.pull_transfer > 0.0 && is_gear(pulling) && is_gear(j) && j != pulling && x.a > 0.0)
    x.a *= theta_[pulling] / theta_[j];
  return x;
}

// The track `y` of a history from mode `i` into mode `j`, predicted over the step under the motion of `j`
// (of moving off for `moving_off`), corrected by GPS and scored by the frequency: the track it leads to, and
// its log-score (GPS and revs) in `score`. `caught`: the share of the way into the clutch that is an
// upshift's declutch caught mid-way (transitions_from).
SpeedSynthesizer::Track SpeedSynthesizer::propagate(const StepInput& in, Track y, int i, int j,
                                                    bool moving_off, double caught,
                                                    double& score) const noexcept {
  const double freq = in.freq;
  predict(y, moving_off ? launch_mode() : j, in.dt);
  // A slipping clutch says only that the car is no faster than first gear turns the revs into: when
  // it bites, at the tracker's short steps, the move-off's guessed speed is known no better than the
  // gap up to the gear's reading, so a hard launch is not lost to the clutch for having gained more
  // than the guess (at 1 Hz and slower that guess already spans a whole launch, and measured better).
  // Only out of the move-off, whose clutch has been slipping: a car rolling declutched that engages a
  // gear within one short step has gained nothing, and with the gap as its spread any gear would fit
  // (fifth gear's reading at 42 km/h taken up from a roll at 7 km/h as the launch's first gear bit).
  if (in.short_step && tuning_.bite_gap > 0.0 && is_gear(j) && i == launch_mode() && std::isfinite(freq) &&
      !in.lacks_first) {
    const double gap = theta_[j] * freq - y.v;
    if (gap > 0.0) y.pvv = std::max(y.pvv, gap * gap);
  }
  double gps_score = 0.0;
  if (in.measure_gps) {
    // GPS pins the speed and the frequency tells the mode; but a history GPS contradicts beyond
    // ordinary jitter (a car at rest while GPS has it moving) pays for that jump once.
    // The fix against the track's speed less what the car gained since it was taken (step_input), no more
    // than a driver's acceleration at three of its spreads (accel_sigma) gains or loses in that time:
    // revs that jump about (a tracker hopping between lines) are no gain of speed.
    const double most = 3.0 * tuning_.accel_sigma * in.lag;
    const double past =
        std::clamp(in.gained + (j == i && is_gear(j) ? theta_[j] * in.revs_gain[j] : 0.0), -most, most);
    const double k = y.pvv / (y.pvv + in.gps_var);
    const double innovation = in.gps - (y.v - past);
    const double z2 = innovation * innovation / (y.pvv + in.gps_var);
    gps_score = -jump_cost(z2);
    // The speed follows a jump; the acceleration learns from no more of it than ordinary jitter.
    const double dead = kDeadZone * kDeadZone;
    y.v += k * innovation;
    y.a += y.pva / (y.pvv + in.gps_var) * innovation *
           (z2 > dead && tuning_.gps_accel_clip > 0.0 ? std::sqrt(dead / z2) : 1.0);
    y.paa -= y.pva * y.pva / (y.pvv + in.gps_var);
    y.pva *= 1.0 - k;
    y.pvv *= 1.0 - k;
    keep_covariance(y);
  }
  double evidence = log_evidence(y, j, freq, in.weight, in.short_step);
  // Into the clutch from a gear: the part of the way that is an upshift's declutch, caught by this
  // reading, scores its revs on their way down from the gear's line (log_declutching) where that
  // explains them better than free revs.
  if (j == 0 && caught > 0.0 && std::isfinite(freq)) {
    const double on_the_way = std::max(evidence, in.weight * log_declutching(i, freq, y));
    evidence = on_the_way + std::log((1.0 - caught) * std::exp(evidence - on_the_way) + caught);
  }
  score = gps_score + evidence;
  return y;
}

// Held in a gear, the car may start braking within the step: the brakes go on within a few tenths of
// a second (a car slowing in gear at 2-3 m/s^2 from one moment to the next), faster than the
// acceleration's drift over accel_time follows. That history, its acceleration's spread opened to
// brake_sigma before the step (about 0 where the car was gaining speed), is weighed by the chance that
// the brakes go on within it (brake_rate, from a foot off the throttle: not while the car gains speed
// in gear) and kept beside the held one as the mixture's first two moments; one whose acceleration
// after the step is no lower than before it is not the brakes'. Without it, braking in gear at the
// tracker's hops is a run of jumps the held acceleration cannot follow, and the clutch takes the first
// falling readings with the acceleration from before the brakes (about 0).
// `x`: gear `j`'s track before the step; `held`: the history held in it, its log-score in `score`, both
// replaced by the mixture's.
SpeedSynthesizer::Track SpeedSynthesizer::with_brakes(const StepInput& in, const Track& x, int j, Track held,
                                                      double& score) const noexcept {
  Track opened = x;
  opened.a = std::min(opened.a, 0.0);
  opened.paa = std::max(opened.paa, tuning_.brake_sigma * tuning_.brake_sigma);
  keep_covariance(opened);
  double braked_score = 0.0;
  const Track braked = propagate(in, opened, j, j, false, 0.0, braked_score);
  const double off_throttle = 0.5 * std::erfc(x.a / std::sqrt(2.0 * x.paa));
  const double p = (1.0 - std::exp(-tuning_.brake_rate * in.dt)) * off_throttle;
  if (p > 1e-12 && braked.a < x.a) {
    const double l_held = std::log1p(-p) + score, l_braked = std::log(p) + braked_score;
    const double top = std::max(l_held, l_braked);
    const double w_held = std::exp(l_held - top), w_braked = std::exp(l_braked - top);
    held = moment_match(held, w_held, braked, w_braked);
    score = top + std::log(w_held + w_braked);
  }
  return held;
}

// The clutch's memory of where its belief came from (pulled_), from this step's histories into it: of each
// gear that pulled at the step's start (its track before the step; the clutch's own history drops the pull),
// the share of the clutch's belief it brought; the share the clutch held already, faded over the step as
// exp(-dt / declutch_time): a declutch longer than a shift is no longer one.
void SpeedSynthesizer::note_pulled(double dt) noexcept {
  const int modes = gears_ + 2;
  double top = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < modes; ++i)
    top = std::max(top, pair_score_[i][0]);
  ModeArray next{};
  if (tuning_.pulled_engage > 0.0 && std::isfinite(top)) {
    const double fade = tuning_.declutch_time > 0.0 ? std::exp(-dt / tuning_.declutch_time) : 0.0;
    double w_sum = 0.0;
    for (int i = 0; i < modes; ++i) {
      if (!std::isfinite(pair_score_[i][0])) continue;
      const double w = std::exp(pair_score_[i][0] - top);
      w_sum += w;
      if (i == 0) {
        for (int g = 1; g < gears_; ++g)
          next[g] += w * fade * pulled_[g];
      } else if (is_gear(i) && i < gears_ && pulling(track_[i])) {
        next[i] += w;
      }
    }
    for (int g = 1; g < gears_; ++g)
      next[g] /= w_sum;
  }
  pulled_ = next;
}

// Every mode sums over its predecessors' histories (pair_score_, pair_track_): its belief, its track matched
// to the mixture's first two moments, and its age.
void SpeedSynthesizer::merge_histories(double dt) noexcept {
  const int modes = gears_ + 2;
  note_pulled(dt);  // before the tracks the histories started from are replaced
  ModeArray log_p{}, next_age{};
  for (int j = 0; j < modes; ++j) {
    double top = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < modes; ++i)
      top = std::max(top, pair_score_[i][j]);
    log_p[j] = top;
    if (!std::isfinite(top)) continue;  // no way into mode j this step
    // Sum over the predecessors, the track matched to the mixture's first two moments.
    ModeArray w{};
    double w_sum = 0.0, v = 0.0, a = 0.0, age = 0.0;
    for (int i = 0; i < modes; ++i) {
      if (!std::isfinite(pair_score_[i][j])) continue;
      w[i] = std::exp(pair_score_[i][j] - top);
      w_sum += w[i];
      if (i == j) age += w[i] * (age_[i] + dt);  // a history that enters mode j starts its clock at 0
      v += w[i] * pair_track_[i][j].v;
      a += w[i] * pair_track_[i][j].a;
    }
    v /= w_sum;
    a /= w_sum;
    next_age[j] = age / w_sum;
    double pvv = 0.0, pva = 0.0, paa = 0.0;
    for (int i = 0; i < modes; ++i) {
      if (w[i] <= 0.0) continue;
      const Track& x = pair_track_[i][j];
      const double share = w[i] / w_sum;
      pvv += share * (x.pvv + (x.v - v) * (x.v - v));
      pva += share * (x.pva + (x.v - v) * (x.a - a));
      paa += share * (x.paa + (x.a - a) * (x.a - a));
    }
    track_[j] = {v, a, pvv, pva, paa};
    keep_covariance(track_[j]);
    log_p[j] = top + std::log(w_sum);
  }
  age_ = next_age;
  double top = -std::numeric_limits<double>::infinity();
  for (int j = 0; j < modes; ++j)
    top = std::max(top, log_p[j]);
  for (int j = 0; j < modes; ++j) {
    prob_[j] = std::isfinite(log_p[j]) ? std::exp(log_p[j] - top) : 0.0;
    track_[j].v = std::max(track_[j].v, 0.0);
  }
  normalise();
  mode_ = map_mode();
}

// A hypothesis grown negligible keeps no history of its own: if the car later shows it, it is entered
// from the belief of the moment, not from a speed drifted apart while nothing supported it. Nor does a
// move-off once a gear has bitten: its guessed speed is superseded by the gear's. Nor, at the tracker's
// short steps through an outage, does the clutch while a gear outweighs it: declutched, the revs say
// nothing of the speed, so its own history has coasted unseen while the gear's revs followed the car
// (a second after a shift under acceleration it still holds a tenth of the belief and lags by a few
// km/h). Mixed into the clutch's speed when the clutch does go out at the next shift, that lag makes
// the gear below the next one fit the revs when the clutch comes back in, and the filter climbs the
// ladder one gear low. At longer steps a declutch and a re-engagement can both fall between two
// readings, and a coasting history is a real alternative.
void SpeedSynthesizer::prune_histories(bool short_step, bool have_gps) noexcept {
  const int modes = gears_ + 2;
  const bool clutch_follows_gear =
      short_step && !have_gps && is_gear(mode_) && prob_[0] < tuning_.clutch_track_share * prob_[mode_];
  for (int j = 0; j < modes; ++j)
    if (j != mode_ && (prob_[j] < kNegligible * prob_[mode_] || (j == launch_mode() && is_gear(mode_)) ||
                       (j == 0 && clutch_follows_gear))) {
      track_[j] = track_[mode_];
      age_[j] = 0.0;
    }
}

// One step of the filter: every mode sums over its predecessors, each one's track predicted over dt under
// the mode's motion and corrected by GPS and the frequency, and keeps the moments of that mixture.
SynthOutput SpeedSynthesizer::filter_step(double dt, double gps, double freq, bool gps_new,
                                          double gps_age) noexcept {
  const StepInput in = step_input(dt, gps, freq, gps_new, gps_age);
  if (in.measure_gps) fix_measured_t_ = fix_stamp(gps_age);
  const int modes = gears_ + 2;
  // A shift is decided by the revs before it, not by the revs it leads to.
  const double shift_freq = std::isfinite(prev_freq_) ? prev_freq_ : freq;
  read_revs(in);
  for (int i = 0; i < modes; ++i) {
    double caught = 0.0;  // share of the way into the clutch that is an upshift's declutch caught mid-way
    transitions_from(i, dt, shift_freq, track_[i].v, row_, caught);
    const double log_pi = std::log(prob_[i]);
    for (int j = 0; j < modes; ++j) {
      pair_score_[i][j] = -std::numeric_limits<double>::infinity();
      if (row_[j] <= 0.0) continue;
      // Moving off: into the launch mode, or through it into a gear within this step.
      const bool moving_off = i == 0 && (j == launch_mode() || (is_gear(j) && track_[i].v < kMovingOffSpeed));
      const Track x = entering(i, j, moving_off, in.have_gps);
      double score = 0.0;
      Track held = propagate(in, x, i, j, moving_off, caught, score);
      if (tuning_.brake_rate > 0.0 && i == j && is_gear(j)) held = with_brakes(in, x, j, held, score);
      pair_score_[i][j] = log_pi + std::log(row_[j]) + score;
      pair_track_[i][j] = held;
    }
  }
  merge_histories(dt);
  prev_freq_ = freq;
  double mean_speed = 0.0;
  for (int j = 0; j < modes; ++j)
    mean_speed += prob_[j] * track_[j].v;
  speed_lag_.note_speed(t_, mean_speed);
  prune_histories(in.short_step, in.have_gps);
  if (in.have_gps) {
    habits_.learn(t_, dt, gps, freq, gps_new, mode_, is_gear(mode_), prob_[mode_], at_idle_, tuning_);
    habits_.learn_shift(is_gear(mode_) ? mode_ : 0, prob_[mode_], freq);
    habits_.learn_pulled_shift(mode_, prob_[mode_], is_gear(mode_), pulling(track_[mode_]),
                               gps >= tuning_.stationary_speed, dt,
                               kPulledDeclutches * tuning_.declutch_time);
    return {gps, gps >= tuning_.stationary_speed ? model_gear(mode_) : 0, SpeedSource::kGps};
  }
  habits_.end_flat_stretch();     // a flat stretch of revs is one GPS saw whole
  habits_.forget_pulled_shift();  // and so is a shift after a pulling gear
  // Through an outage the output policy chooses the speed from the belief in the modes and their tracks.
  ModeArray speed{}, speed_var{};
  for (int j = 0; j < modes; ++j) {
    speed[j] = track_[j].v;
    speed_var[j] = track_[j].pvv;
  }
  const auto n = static_cast<std::size_t>(modes);
  return SynthOutputPolicy::outage({prob_.data(), n}, {speed.data(), n}, {speed_var.data(), n}, gears_,
                                   {model_gear_.data(), n}, mode_, tuning_);
}

}  // namespace gearpulse
