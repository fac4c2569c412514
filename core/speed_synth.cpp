// The synthesis's mode filter (SpeedSynthesizer, core/speed_synth.hpp): its state (construction, reset, the
// belief as the accessors read it, a track's covariance kept a covariance) and step(), which handles time,
// tracker gaps and the hold without a ladder around one step of the filter (synth_step.cpp).
#include "core/speed_synth.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "core/synth_constants.hpp"

namespace gearpulse {

using namespace synth;

namespace {

constexpr double kMinProb = 1e-9;         // keeps every mode recoverable
constexpr double kInitialSpeedVar = 1.0;  // (m/s)^2: a cold start is most likely near standstill
constexpr double kMaxSpeedVar = 25.0;     // (m/s)^2: a coasting guess is never "anything at all"

}  // namespace

// Keeps a track's covariance a covariance. The speed variance is capped at kMaxSpeedVar by scaling the
// speed axis (its covariance with the acceleration shrinks with it, as conditioning would), and rounding
// in the updates may never leave a negative variance or a correlation beyond 1: from such a matrix the
// next Kalman gain exceeds 1 and the track runs off to any speed.
void SpeedSynthesizer::keep_covariance(Track& x) noexcept {
  constexpr double kMinVar = 1e-9;
  if (x.pvv > kMaxSpeedVar) {
    x.pva *= std::sqrt(kMaxSpeedVar / x.pvv);
    x.pvv = kMaxSpeedVar;
  }
  x.pvv = std::max(x.pvv, kMinVar);
  x.paa = std::max(x.paa, kMinVar);
  const double bound = 0.999 * std::sqrt(x.pvv * x.paa);
  x.pva = std::clamp(x.pva, -bound, bound);
}

// The track with the first two moments of the mixture of `x` and `y` weighed `wx` and `wy`.
SpeedSynthesizer::Track SpeedSynthesizer::moment_match(const Track& x, double wx, const Track& y,
                                                       double wy) noexcept {
  const double sx = wx / (wx + wy), sy = wy / (wx + wy);
  Track m{sx * x.v + sy * y.v, sx * x.a + sy * y.a, 0.0, 0.0, 0.0};
  for (const auto& [t, share] : {std::pair{x, sx}, std::pair{y, sy}}) {
    m.pvv += share * (t.pvv + (t.v - m.v) * (t.v - m.v));
    m.pva += share * (t.pva + (t.v - m.v) * (t.a - m.a));
    m.paa += share * (t.paa + (t.a - m.a) * (t.a - m.a));
  }
  keep_covariance(m);
  return m;
}

SpeedSynthesizer::SpeedSynthesizer(std::shared_ptr<const GearModel> model, const SynthTuning& tuning)
    : tuning_(tuning), seen_(tuning.seen_gear_fixes) {
  speed_lag_.set_significance(tuning.speed_lag_significance);
  if (model && model->gears.size() <= static_cast<std::size_t>(kMaxGears)) model_ = std::move(model);
  extras_ = read_model_extras(model_.get());
  if (tuning_.fit_launch_gears > 0.0) launches_.seed(extras_.launch_base, extras_.launch_counts);
  read_top_gear_revs();
  load_model();
  reset();
}

void SpeedSynthesizer::reset() noexcept {
  // A cold start is most likely a car at rest, out of gear: until the first evidence the belief says so,
  // rather than "in the most used gear at zero speed".
  constexpr double kColdStartRest = 0.5;
  prob_.fill(0.0);
  for (int j = 0; j <= gears_; ++j)
    prob_[j] = j == 0 ? std::max(weight_[0], kColdStartRest) : weight_[j] * (1.0 - kColdStartRest);
  normalise();
  track_.fill(Track{0.0, 0.0, kInitialSpeedVar, 0.0, tuning_.accel_sigma * tuning_.accel_sigma});
  age_.fill(0.0);
  pulled_.fill(0.0);
  habits_.forget_pulled_shift();
  started_ = false;
  informed_ = false;
  t_ = 0.0;
  mode_ = 0;
  habits_.forget_last_fix();
  output_.forget_gps();
  prev_freq_ = std::numeric_limits<double>::quiet_NaN();
  freq_seen_t_ = -std::numeric_limits<double>::infinity();
  fix_measured_t_ = -std::numeric_limits<double>::infinity();
  lost_for_ = 0.0;
  hop_ = 0.0;
  in_gap_ = false;
  habits_.end_flat_stretch();
  unlearned_fix_ = {};
  launches_.abort();
  launch_revs_ = 0.0;
  launch_speed_ = 0.0;
  launch_revs_t_ = std::numeric_limits<double>::infinity();
  // Kept: speed_lag_ and revs_interval_, properties of the feed.
  last_ = {};
}

double SpeedSynthesizer::mode_probability(int mode) const noexcept {
  if (mode == 0) return prob_[0] + (gears_ > 0 ? prob_[static_cast<std::size_t>(launch_mode())] : 0.0);
  for (int j = 1; j <= gears_ && mode > 0; ++j)
    if (model_gear_[j] == mode) return prob_[j];
  return 0.0;
}

SpeedSynthesizer::ModeTrack SpeedSynthesizer::mode_track(int position) const noexcept {
  if (position < 0 || position > gears_ + 1) return {};
  const Track& x = track_[static_cast<std::size_t>(position)];
  return {x.v, x.a, std::sqrt(x.paa)};
}

double SpeedSynthesizer::idle_freq() const noexcept {
  return habits_.idle_freq();
}

void SpeedSynthesizer::normalise() noexcept {
  const int modes = gears_ > 0 ? gears_ + 2 : 1;
  double total = 0.0;
  for (int j = 0; j < modes; ++j)
    total += prob_[j];
  if (!(total > 0.0) || !std::isfinite(total)) {
    for (int j = 0; j < modes; ++j)
      prob_[j] = weight_[j];
    total = 1.0;
  }
  for (int j = 0; j < modes; ++j)
    prob_[j] = std::max(prob_[j] / total, kMinProb);
}

int SpeedSynthesizer::map_mode() const noexcept {
  int best = 0;
  for (int j = 1; j <= gears_ + (gears_ > 0 ? 1 : 0); ++j)
    if (prob_[j] > prob_[best]) best = j;
  return best;
}

SynthOutput SpeedSynthesizer::in_gap_output(double elapsed) const noexcept {
  const int modes = gears_ + 2;
  ModeArray speed{}, speed_var{};
  for (int j = 0; j < modes; ++j) {
    Track x = track_[j];
    predict(x, j, elapsed);
    speed[j] = std::max(x.v, 0.0);
    speed_var[j] = x.pvv;
  }
  const auto n = static_cast<std::size_t>(modes);
  return SynthOutputPolicy::outage({prob_.data(), n}, {speed.data(), n}, {speed_var.data(), n}, gears_,
                                   {model_gear_.data(), n}, mode_, tuning_);
}

SynthOutput SpeedSynthesizer::step(double t, double gps_speed, double freq, bool gps_new,
                                   double gps_age) noexcept {
  if (!std::isfinite(t)) return last_;
  double dt = started_ ? t - t_ : 0.0;
  if (dt < 0.0) dt = 0.0;
  if (!std::isfinite(freq) || freq < 0.0) freq = std::numeric_limits<double>::quiet_NaN();
  const bool have_gps = std::isfinite(gps_speed) && gps_speed >= 0.0;
  // Through an outage, a hop the tracker refused, within a gap no longer than the tracker's (kTrackerGap),
  // is no step of the filter: a gap says nothing of the mode, and stepped hop by hop the transitions over
  // it would merge every mode's history with the histories entering it, which only the reading after the
  // gap can tell apart (a gear held through the gap, its track carried unchanged, from a gear entered from
  // the clutch's). The next reading takes the gap as one step (the motion and the rates are continuous in
  // time); meanwhile the output is the belief's, each track predicted to this hop. Not while GPS gives a
  // speed: deferred there too, the daemon's cadence erred more (synthesis-experiments.md). The step after
  // the gap carries the hop's evidence, so a gap is deferred only after a step of some length.
  if (started_ && informed_ && gears_ > 0 && tuning_.gap_one_step > 0.0 && !std::isfinite(freq) &&
      !have_gps && dt > 0.0 && hop_ > 0.0 && t - freq_seen_t_ <= kTrackerGap + 1e-6) {
    in_gap_ = true;
    last_ = in_gap_output(dt);
    return last_;
  }
  if (!started_ || t > t_) t_ = t;
  started_ = true;
  if (dt > tuning_.max_gap) {
    for (int j = 0; j < kModes; ++j)
      prob_[j] = weight_[j];
    for (Track& x : track_)
      x = {x.v, 0.0, kMaxSpeedVar, 0.0, tuning_.accel_sigma * tuning_.accel_sigma};
    age_.fill(0.0);
    habits_.forget_last_fix();
    habits_.end_flat_stretch();     // a flat stretch of revs is not seen whole across the gap
    habits_.forget_pulled_shift();  // nor a shift after a pulling gear
    pulled_.fill(0.0);              // a pull before the gap says nothing after it
    launches_.abort();              // the launch's shifts in the gap are unseen
    dt = 0.0;
  }
  if (!in_gap_) hop_ = dt;
  in_gap_ = false;
  lost_for_ = std::isfinite(freq) ? 0.0 : t_ - freq_seen_t_;
  if (std::isfinite(freq)) freq_seen_t_ = t_;
  if (have_gps) {
    output_.note_gps(t, gps_speed);  // for an outage without a ladder, whenever the ladder went
  }

  // Before the first fix or frequency reading nothing is known: no speed, not a guess.
  informed_ = informed_ || have_gps || std::isfinite(freq);
  SynthOutput out;
  if (!informed_) {
    out = {0.0, 0, SpeedSource::kNone};
  } else if (gears_ == 0) {
    launches_.abort();  // no ladder to follow a launch on
    out = output_.hold(t, have_gps ? gps_speed : std::numeric_limits<double>::quiet_NaN(), tuning_);
    // Before a model, GPS still shows the car standing: the idle is learned as with one (no mode is held).
    if (have_gps) habits_.learn(t_, dt, gps_speed, freq, gps_new, 0, false, 0.0, false, tuning_);
  } else {
    speed_lag_.note_freq(t_, freq);
    if (!std::isfinite(gps_age)) gps_age = 0.0;
    out = filter_step(dt, have_gps ? gps_speed : std::numeric_limits<double>::quiet_NaN(), freq, gps_new,
                      gps_age);
    observe_launch(have_gps ? gps_speed : std::numeric_limits<double>::quiet_NaN(), freq, gps_new);
    if (have_gps && gps_new) {
      observe_gear(gps_speed, freq, measured_fix_lag(gps_age));
      unlearned_fix_ = {t_ - gps_age, gps_speed};
    }
    // A fix teaches the lag once the revs at its stamp are noted: at once, or at the first step at or after
    // a stamp later than the step it came with.
    if (unlearned_fix_.t <= t_) {
      speed_lag_.learn(unlearned_fix_.t, unlearned_fix_.speed,
                       {theta_.data() + 1, static_cast<std::size_t>(gears_)});
      unlearned_fix_ = {};
    }
  }
  last_ = out;
  return out;
}

}  // namespace gearpulse
