#include "core/imm_speed_synth.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace gearpulse {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
// Fixes this far apart give the acceleration learned (closer, GPS noise dominates; farther, it averages
// away the accelerations that matter).
constexpr double kMinAccelSpan = 0.5, kMaxAccelSpan = 3.0;  // s
// Floors on the model's noise levels: integer km/h logs and GPS noise; tracker jitter.
constexpr double kMinSpeedSigma = 0.15;  // m/s
constexpr double kMinFreqSigma = 0.05;   // Hz
constexpr double kMaxSpeed = 100.0;      // m/s: a GPS speed above this is not a car's

}  // namespace

ImmSpeedSynthesizer::ImmSpeedSynthesizer(std::shared_ptr<const GearModel> model) {
  filter_.reset();
  set_model(std::move(model));
}

bool ImmSpeedSynthesizer::set_model(std::shared_ptr<const GearModel> model) noexcept {
  if (model && model->gears.size() > GearModel::kMaxGears) return false;
  GearLadder ladder;
  if (model) {
    ladder.gears = static_cast<int>(model->gears.size());
    for (int g = 1; g <= ladder.gears; ++g) {
      const Gear& gear = model->gears[static_cast<std::size_t>(g - 1)];
      ladder.theta[static_cast<std::size_t>(g)] = gear.theta;
      ladder.theta_se[static_cast<std::size_t>(g)] = std::isfinite(gear.std_error) ? gear.std_error : 0.0;
    }
    ladder.sigma_speed =
        std::max(std::isfinite(model->sigma_speed) ? model->sigma_speed : 0.0, kMinSpeedSigma);
    ladder.sigma_freq = std::max(std::isfinite(model->sigma_freq) ? model->sigma_freq : 0.0, kMinFreqSigma);
    learner_.seed_from(*model);
  }
  filter_.set_ladder(ladder);
  gears_ = ladder.gears;
  model_ = std::move(model);
  return true;
}

void ImmSpeedSynthesizer::reset() noexcept {
  filter_.reset();
  started_ = informed_ = false;
  t_ = 0.0;
  fix_speed_ = held_speed_ = -1.0;
  last_ = {};
}

double ImmSpeedSynthesizer::mode_probability(int mode) const noexcept {
  if (mode < 0 || mode > gears_) return 0.0;
  if (mode == 0) return filter_.probability(0) + filter_.probability(filter_.launch());
  return filter_.probability(mode);
}

SynthOutput ImmSpeedSynthesizer::hold_step(double t, double gps) const noexcept {
  if (std::isfinite(gps)) return {gps, 0, SpeedSource::kGps};
  if (held_speed_ < 0.0) return {0.0, 0, SpeedSource::kNone};
  const double coasted = std::max(0.0, t - held_t_ - kHoldTime);
  const double v = std::max(0.0, held_speed_ + learner_.habits().coast_accel * coasted);
  return {v < kStanding ? 0.0 : v, 0, SpeedSource::kCoast};
}

void ImmSpeedSynthesizer::learn(double dt, double gps, bool gps_new, double freq) noexcept {
  double accel = kNan;
  if (gps_new) {
    const double span = t_ - fix_t_;
    if (fix_speed_ >= 0.0 && span >= kMinAccelSpan && span <= kMaxAccelSpan)
      accel = (gps - fix_speed_) / span;
    if (fix_speed_ < 0.0 || span >= kMinAccelSpan) fix_speed_ = gps, fix_t_ = t_;
  }
  int mode = -1;
  if (gears_ > 0) {
    const int top = filter_.most_probable();
    if (filter_.probability(top) >= kSure) mode = top;
  } else if (gps < kStanding) {
    mode = 0;  // without a ladder only the idle is learned
  }
  learner_.observe(dt, mode, filter_.launch(), gps, freq, accel);
}

SynthOutput ImmSpeedSynthesizer::step(double t, double gps_speed, double freq, bool gps_new) noexcept {
  if (!std::isfinite(t)) return last_;
  double dt = started_ ? t - t_ : 0.0;
  const bool first = !started_;
  if (dt < 0.0) dt = 0.0;
  if (first || t > t_) t_ = t;
  started_ = true;
  if (dt > kMaxGap) {  // the speed is unknown after a long gap; the belief starts over
    filter_.reset();
    fix_speed_ = -1.0;
    dt = 0.0;
  }
  if (!std::isfinite(freq) || freq <= 0.0 || freq > 1e4) freq = kNan;
  const bool have_gps = std::isfinite(gps_speed) && gps_speed >= 0.0 && gps_speed < kMaxSpeed;
  if (have_gps) {
    held_speed_ = gps_speed;
    held_t_ = t;
  }
  informed_ = informed_ || have_gps || std::isfinite(freq);
  if (!informed_) return last_ = {0.0, 0, SpeedSource::kNone};

  if (gears_ > 0) {
    const double evidence = first ? 1.0 : std::min(1.0, dt / ModeFilter::kEvidenceTime);
    filter_.step(dt, have_gps && gps_new ? gps_speed : kNan, freq, learner_.habits(), evidence);
  }
  if (have_gps) learn(dt, gps_speed, gps_new, freq);

  if (gears_ == 0) return last_ = hold_step(t, have_gps ? gps_speed : kNan);
  const int top = filter_.most_probable();
  const int gear = filter_.is_gear(top) ? top : 0;
  if (have_gps) return last_ = {gps_speed, gear, SpeedSource::kGps};
  const double speed = filter_.mean_speed();
  return last_ = {speed, gear, gear > 0 ? SpeedSource::kEngine : SpeedSource::kCoast,
                  filter_.speed_spread(speed)};
}

}  // namespace gearpulse
