#include "core/speed_synth.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace gearpulse {
namespace {

constexpr double kMinProb = 1e-9;             // keeps every mode recoverable
constexpr double kInitialSpeedVar = 1.0;      // (m/s)^2: a cold start is most likely near standstill
constexpr double kMaxSpeedVar = 16.0;         // (m/s)^2: a coasting guess is never "anything at all"
constexpr double kLostGearLikelihood = 0.05;  // relative evidence for a gear when the frequency is lost
constexpr double kDefaultClutchShare =
    0.15;                               // clutch-out share when the model gives none (cf. beta, eq. (6))
constexpr double kMinGearShare = 0.02;  // no gear is ever ruled out by its training weight

double gaussian(double x, double var) noexcept {
  return std::exp(-0.5 * x * x / var) / std::sqrt(2.0 * std::numbers::pi * var);
}

}  // namespace

std::string_view source_name(SpeedSource source) noexcept {
  switch (source) {
    case SpeedSource::kGps:
      return "gps";
    case SpeedSource::kEngine:
      return "engine";
    case SpeedSource::kCoast:
      return "coast";
    case SpeedSource::kNone:
      break;
  }
  return "none";
}

SpeedSynthesizer::SpeedSynthesizer(std::shared_ptr<const GearModel> model, const SynthTuning& tuning)
    : tuning_(tuning) {
  if (model && model->gears.size() <= static_cast<std::size_t>(kMaxGears)) model_ = std::move(model);
  load_model(model_.get());
  reset();
}

void SpeedSynthesizer::load_model(const GearModel* model) noexcept {
  gears_ = model ? static_cast<int>(model->gears.size()) : 0;
  theta_.fill(0.0);
  weight_.fill(0.0);
  double total = 0.0;
  for (int j = 1; j <= gears_; ++j) {
    theta_[j] = model->gears[static_cast<std::size_t>(j - 1)].theta;
    weight_[j] = std::max(model->gears[static_cast<std::size_t>(j - 1)].weight, kMinGearShare);
    total += weight_[j];
  }
  const double clutch = model && model->outlier_weight > 0.0 ? std::clamp(model->outlier_weight, 0.05, 0.5)
                                                             : kDefaultClutchShare;
  for (int j = 1; j <= gears_; ++j)
    weight_[j] *= (1.0 - clutch) / total;
  weight_[0] = gears_ > 0 ? clutch : 1.0;
  sigma_v_ = std::max(model ? model->sigma_speed : 0.0, tuning_.min_speed_sigma);
  sigma_s_ = model ? std::max(model->sigma_freq, 0.0) : 0.0;
}

void SpeedSynthesizer::reset() noexcept {
  for (int j = 0; j < kModes; ++j)
    prob_[j] = j <= gears_ ? weight_[j] : 0.0;
  track_ = 0.0;
  track_var_ = kInitialSpeedVar;
  started_ = false;
  t_ = 0.0;
  out_speed_ = 0.0;
  accel_ = 0.0;
  mode_ = 0;
  last_ = {};
}

bool SpeedSynthesizer::set_model(std::shared_ptr<const GearModel> model) noexcept {
  if (model && model->gears.size() > static_cast<std::size_t>(kMaxGears)) return false;
  const int old_gears = gears_;
  const ModeArray old_theta = theta_, old_prob = prob_;
  model_ = std::move(model);
  load_model(model_.get());
  // Carry the belief over: each old gear hands its probability to the new gear with the nearest theta
  // (in ratio), so a retrained model of the same car continues exactly where it was. The speed track is
  // the car's, not the model's, and stays.
  prob_.fill(0.0);
  prob_[0] = old_prob[0];
  for (int i = 1; i <= old_gears && gears_ > 0; ++i) {
    int best = 1;
    for (int j = 2; j <= gears_; ++j) {
      if (std::abs(std::log(theta_[j] / old_theta[i])) < std::abs(std::log(theta_[best] / old_theta[i])))
        best = j;
    }
    prob_[best] += old_prob[i];
  }
  if (gears_ == 0) {
    prob_[0] = 1.0;
  } else if (old_gears == 0) {
    for (int j = 0; j <= gears_; ++j)
      prob_[j] = weight_[j];
  }
  normalise();
  mode_ = map_mode();
  return true;
}

double SpeedSynthesizer::idle_freq() const noexcept {
  return idle_count_ > 0.0 ? idle_mean_ : std::numeric_limits<double>::quiet_NaN();
}

double SpeedSynthesizer::freq_sigma(double freq) const noexcept {
  return std::max(sigma_s_, tuning_.min_freq_rel * freq);
}

// Likelihood of clutch-out, in the speed units of the gear likelihoods: the density of the engine
// frequency while declutched, mapped to speed by the top gear's scale. The engine falls to idle (a spike,
// as the paper's g() has one at standstill, section 3.1) or runs free anywhere in its range (flat).
double SpeedSynthesizer::clutch_likelihood(double freq) const noexcept {
  const double flat = 1.0 / std::max({freq_max_, freq, 1.0});
  double density = flat;
  if (idle_count_ > 0.0) {
    const double idle_sd = std::max(std::sqrt(idle_var_), 0.02 * idle_mean_);
    density = tuning_.idle_weight * gaussian(freq - idle_mean_, idle_sd * idle_sd) +
              (1.0 - tuning_.idle_weight) * flat;
  }
  return density / theta_[gears_];
}

void SpeedSynthesizer::normalise() noexcept {
  double total = 0.0;
  for (int j = 0; j <= gears_; ++j)
    total += prob_[j];
  if (!(total > 0.0) || !std::isfinite(total)) {
    for (int j = 0; j <= gears_; ++j)
      prob_[j] = weight_[j];
    total = 1.0;
  }
  for (int j = 0; j <= gears_; ++j)
    prob_[j] = std::max(prob_[j] / total, kMinProb);
}

int SpeedSynthesizer::map_mode() const noexcept {
  int best = 0;
  for (int j = 1; j <= gears_; ++j)
    if (prob_[j] > prob_[best]) best = j;
  return best;
}

// Mode transitions over dt: a gear is left for the clutch or for a neighbouring gear (a quick shift
// between two samples); the clutch is left for any gear, in proportion to how much each is used.
void SpeedSynthesizer::predict_modes(double dt) noexcept {
  if (dt <= 0.0) return;
  const double leave_gear = 1.0 - std::exp(-tuning_.gear_leave_rate * dt);
  const double leave_clutch = 1.0 - std::exp(-tuning_.clutch_leave_rate * dt);
  scratch_.fill(0.0);
  scratch_[0] = prob_[0] * (1.0 - leave_clutch);
  for (int j = 1; j <= gears_; ++j)
    scratch_[j] = prob_[0] * leave_clutch * weight_[j] / (1.0 - weight_[0]);
  for (int i = 1; i <= gears_; ++i) {
    const int neighbours = (i > 1) + (i < gears_);
    const double to_clutch = neighbours > 0 ? 0.6 : 1.0;
    scratch_[i] += prob_[i] * (1.0 - leave_gear);
    scratch_[0] += prob_[i] * leave_gear * to_clutch;
    if (i > 1) scratch_[i - 1] += prob_[i] * leave_gear * (1.0 - to_clutch) / neighbours;
    if (i < gears_) scratch_[i + 1] += prob_[i] * leave_gear * (1.0 - to_clutch) / neighbours;
  }
  prob_ = scratch_;
}

void SpeedSynthesizer::update_accel(double dt, double speed) noexcept {
  if (dt <= 0.0) return;
  const double a = std::clamp((speed - out_speed_) / dt, -tuning_.max_accel, tuning_.max_accel);
  const double k = 1.0 - std::exp(-dt / tuning_.accel_time);
  accel_ += k * (a - accel_);
}

void SpeedSynthesizer::learn(double dt, double gps, double freq) noexcept {
  if (!std::isfinite(freq)) return;
  freq_max_ = std::max(freq_max_, freq);
  if (gps >= tuning_.stationary_speed || freq <= 0.0) return;
  // Idle frequency: a running mean over standing samples, forgetting slowly (about a minute) so that a
  // warm engine's lower idle replaces the cold-start one.
  constexpr double kIdleMemory = 60.0;
  idle_count_ = std::min(idle_count_ + 1.0, kIdleMemory / std::max(dt, 0.1));
  const double k = 1.0 / idle_count_;
  const double d = freq - idle_mean_;
  idle_mean_ += k * d;
  idle_var_ += k * (d * d * (1.0 - k) - idle_var_);
}

SynthOutput SpeedSynthesizer::gps_step(double dt, double gps, double freq) noexcept {
  predict_modes(dt);
  if (std::isfinite(freq) && gears_ > 0) {
    const double sf = freq_sigma(freq);
    prob_[0] *= clutch_likelihood(freq);
    for (int j = 1; j <= gears_; ++j) {
      const double s = sigma_v_ * sigma_v_ + theta_[j] * theta_[j] * sf * sf;
      prob_[j] *= gaussian(gps - theta_[j] * freq, s);
    }
    normalise();
  }
  track_ = gps;
  track_var_ = sigma_v_ * sigma_v_;
  learn(dt, gps, freq);
  update_accel(dt, gps);
  mode_ = map_mode();
  return {gps, gps >= tuning_.stationary_speed ? mode_ : 0, SpeedSource::kGps};
}

SynthOutput SpeedSynthesizer::engine_step(double dt, double freq) noexcept {
  const bool have_freq = std::isfinite(freq);
  if (have_freq) freq_max_ = std::max(freq_max_, freq);
  predict_modes(dt);
  // Declutched at (or without) idle the driver is braking to a stop: keep the recent deceleration,
  // within ordinary bounds. Declutched above idle is a shift: the car rolls on, slowing gently.
  const double idle_sd = std::max(std::sqrt(idle_var_), 0.02 * idle_mean_);
  const bool at_idle = !have_freq || (idle_count_ > 0.0 && freq < idle_mean_ + 3.0 * idle_sd);
  const double decel = at_idle ? std::clamp(-accel_, tuning_.stop_decel_min, tuning_.stop_decel_max)
                               : tuning_.shift_coast_decel;
  const double q = tuning_.accel_sigma * dt * tuning_.accel_sigma * dt;
  const double var = std::min(track_var_ + q, kMaxSpeedVar);
  const double in_gear = std::max(0.0, track_ + accel_ * dt);

  mode_speed_[0] = std::max(0.0, track_ - decel * dt);
  mode_var_[0] = var;
  if (have_freq) {
    const double sf = freq_sigma(freq);
    prob_[0] *= clutch_likelihood(freq);
    for (int j = 1; j <= gears_; ++j) {
      const double z = theta_[j] * freq;
      const double s = var + theta_[j] * theta_[j] * sf * sf + 1e-6;
      prob_[j] *= gaussian(z - in_gear, s);
      const double k = var / s;
      mode_speed_[j] = in_gear + k * (z - in_gear);
      mode_var_[j] = (1.0 - k) * var;
    }
  } else {
    for (int j = 1; j <= gears_; ++j) {
      prob_[j] *= kLostGearLikelihood;
      mode_speed_[j] = in_gear;
      mode_var_[j] = var;
    }
  }
  normalise();
  // Collapse the modes into the shared track (moment matching); the output follows the likeliest mode.
  track_ = 0.0;
  for (int j = 0; j <= gears_; ++j)
    track_ += prob_[j] * mode_speed_[j];
  track_var_ = 0.0;
  for (int j = 0; j <= gears_; ++j) {
    const double d = mode_speed_[j] - track_;
    track_var_ += prob_[j] * (mode_var_[j] + d * d);
  }
  track_var_ = std::min(track_var_, kMaxSpeedVar);
  const int previous_mode = mode_;
  mode_ = map_mode();
  if (mode_ == 0) {
    // Standing still is certain enough: do not let the guess drift while the car waits at a light.
    if (mode_speed_[0] <= 0.0) track_var_ = std::min(track_var_, kInitialSpeedVar);
    accel_ *= std::exp(-dt / tuning_.accel_time);
    return {mode_speed_[0], 0, SpeedSource::kCoast};
  }
  // A change of gear hypothesis moves the output by a step that is no acceleration of the car.
  if (mode_ == previous_mode && last_.source == SpeedSource::kEngine) update_accel(dt, mode_speed_[mode_]);
  return {mode_speed_[mode_], mode_, SpeedSource::kEngine};
}

SynthOutput SpeedSynthesizer::step(double t, double gps_speed, double freq) noexcept {
  if (!std::isfinite(t)) return last_;
  double dt = started_ ? t - t_ : 0.0;
  if (dt < 0.0) dt = 0.0;
  if (started_ && t > t_) t_ = t;
  if (!started_) {
    t_ = t;
    started_ = true;
  }
  if (dt > tuning_.max_gap) {
    for (int j = 0; j <= gears_; ++j)
      prob_[j] = weight_[j];
    track_var_ = kMaxSpeedVar;
    accel_ = 0.0;
    dt = 0.0;
  }
  if (!std::isfinite(freq) || freq < 0.0) freq = std::numeric_limits<double>::quiet_NaN();
  const bool have_gps = std::isfinite(gps_speed) && gps_speed >= 0.0;

  SynthOutput out;
  if (have_gps) {
    out = gps_step(dt, gps_speed, freq);
  } else if (gears_ == 0) {
    out = {0.0, 0, SpeedSource::kNone};
  } else {
    out = engine_step(dt, freq);
  }
  out_speed_ = out.speed;
  last_ = out;
  return out;
}

}  // namespace gearpulse
