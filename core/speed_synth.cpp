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
  // A gear used for a small share of the time is one a driver passes through quickly (first gear when
  // moving off): its dwell time, hence its rate of being left, scales with its weight alpha_i.
  leave_rate_.fill(0.0);
  for (int j = 1; j <= gears_; ++j) {
    constexpr double kMaxRateFactor = 5.0;
    const double typical = (1.0 - clutch) / gears_;
    leave_rate_[j] =
        tuning_.gear_leave_rate * std::clamp(typical / weight_[j], 1.0 / kMaxRateFactor, kMaxRateFactor);
  }
  sigma_v_ = std::max(model ? model->sigma_speed : 0.0, tuning_.min_speed_sigma);
  sigma_s_ = model ? std::max(model->sigma_freq, 0.0) : 0.0;
}

void SpeedSynthesizer::reset() noexcept {
  for (int j = 0; j < kModes; ++j)
    prob_[j] = j <= gears_ ? weight_[j] : 0.0;
  speed_.fill(0.0);
  var_.fill(kInitialSpeedVar);
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
  const ModeArray old_theta = theta_, old_prob = prob_, old_speed = speed_, old_var = var_;
  model_ = std::move(model);
  load_model(model_.get());
  // Carry the belief over: each old gear hands its probability to the new gear with the nearest theta
  // (in ratio) with its speed track, so a retrained model of the same car continues where it was.
  prob_.fill(0.0);
  prob_[0] = old_prob[0];
  for (int j = 1; j <= gears_; ++j) {
    speed_[j] = out_speed_;
    var_[j] = old_var[0];
  }
  next_p_.fill(0.0);  // strongest old gear handed to each new gear so far
  for (int i = 1; i <= old_gears && gears_ > 0; ++i) {
    int best = 1;
    for (int j = 2; j <= gears_; ++j) {
      if (std::abs(std::log(theta_[j] / old_theta[i])) < std::abs(std::log(theta_[best] / old_theta[i])))
        best = j;
    }
    prob_[best] += old_prob[i];
    if (old_prob[i] > next_p_[best]) {
      next_p_[best] = old_prob[i];
      speed_[best] = old_speed[i];
      var_[best] = old_var[i];
    }
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

// Spread of the idle frequency, bounded so that a cold start's high idle or a single blip cannot make the
// spike cover the whole driving range.
double SpeedSynthesizer::idle_sd() const noexcept {
  return std::clamp(std::sqrt(idle_var_), 0.03 * idle_mean_, 0.1 * idle_mean_);
}

// Likelihood of clutch-out, in the speed units of the gear likelihoods: the density of the engine
// frequency while declutched, mapped to speed by the top gear's scale. The engine falls to idle (a spike,
// as the paper's g() has one at standstill, section 3.1) or runs free anywhere in its range (flat).
double SpeedSynthesizer::clutch_likelihood(double freq) const noexcept {
  const double flat = 1.0 / std::max({freq_max_, freq, 1.0});
  double density = flat;
  if (idle_count_ > 0.0) {
    const double sd = idle_sd();
    density = tuning_.idle_weight * gaussian(freq - idle_mean_, sd * sd) + (1.0 - tuning_.idle_weight) * flat;
  }
  return density / theta_[gears_];
}

// Relative chance of driving in `gear` with the engine at `freq`: near idle a driver declutches rather than
// lug the engine, except when creeping in first gear.
double SpeedSynthesizer::lugging(int gear, double freq) const noexcept {
  if (idle_count_ <= 0.0) return 1.0;
  const double x = (freq - idle_mean_) / idle_sd();
  const double at_idle = 1.0 / (1.0 + std::exp(3.0 * (x - 2.5)));  // ~1 up to 2 sd above idle, ~0 past 3.5
  const double floor = gear == 1 ? tuning_.lugging_first : tuning_.lugging_other;
  return 1.0 - (1.0 - floor) * at_idle;
}

// How much more likely an upshift (and less likely a downshift) is at this engine frequency than at the
// frequency this driver usually runs at in gear: drivers shift up as revs rise and down as they sag.
double SpeedSynthesizer::shift_urge(double freq) const noexcept {
  constexpr double kMinDriveSamples = 20.0;
  if (!std::isfinite(freq) || drive_count_ < kMinDriveSamples) return 1.0;
  const double sd = std::max(std::sqrt(drive_var_), 0.05 * drive_mean_);
  return std::exp(std::clamp((freq - drive_mean_) / sd, -3.0, 3.0));
}

namespace {

// Running mean and variance with a bounded memory (in samples).
void accumulate(double x, double& mean, double& var, double& count, double memory) noexcept {
  count = std::min(count + 1.0, memory);
  const double k = 1.0 / count;
  const double d = x - mean;
  mean += k * d;
  var += k * (d * d * (1.0 - k) - var);
}

constexpr double kMinShifts = 3.0;  // shifts seen before the learned shift points are trusted

}  // namespace

// Hazard multipliers of shifting up or down at this frequency, from the frequencies at which this driver
// was seen shifting (drivers shift up as revs reach their habit, down as revs sag to theirs). Before any
// shift was seen, the frequency usually run in gear stands in for both.
double SpeedSynthesizer::upshift_factor(double freq) const noexcept {
  if (!std::isfinite(freq)) return 1.0;
  if (up_count_ < kMinShifts) return shift_urge(freq);
  const double sd = std::max(std::sqrt(up_var_), 0.08 * up_mean_);
  return std::exp(std::clamp((freq - up_mean_) / sd, -1.5, 3.0));
}

double SpeedSynthesizer::downshift_factor(double freq) const noexcept {
  if (!std::isfinite(freq)) return 1.0;
  if (down_count_ < kMinShifts) return 1.0 / shift_urge(freq);
  const double sd = std::max(std::sqrt(down_var_), 0.08 * down_mean_);
  return std::exp(std::clamp(-(freq - down_mean_) / sd, -1.5, 3.0));
}

// Called under GPS after each step: notes the frequency at which a confidently held gear was left for
// its neighbour.
void SpeedSynthesizer::learn_shift(double freq) noexcept {
  constexpr double kSure = 0.8;
  constexpr double kShiftMemory = 50.0;  // shifts
  if (mode_ == 0 || prob_[mode_] < kSure || !std::isfinite(freq)) return;
  if (sure_gear_ > 0 && mode_ == sure_gear_ + 1) {
    accumulate(sure_gear_freq_, up_mean_, up_var_, up_count_, kShiftMemory);
  } else if (sure_gear_ > 0 && mode_ == sure_gear_ - 1) {
    accumulate(sure_gear_freq_, down_mean_, down_var_, down_count_, kShiftMemory);
  }
  sure_gear_ = mode_;
  sure_gear_freq_ = freq;
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

// Mode transitions over dt: a gear is left for the clutch or for a neighbouring gear (a quick shift between
// two samples, up more likely at high revs, down at low revs); the clutch is left for any gear, in
// proportion to how much each is used.
void SpeedSynthesizer::compute_transitions(double dt, double freq) noexcept {
  constexpr double kToClutch = 0.6, kToNeighbour = 0.2;
  for (auto& row : trans_)
    row.fill(0.0);
  dt = std::max(dt, 0.0);
  const double up_factor = upshift_factor(freq), down_factor = downshift_factor(freq);
  const double leave_clutch = 1.0 - std::exp(-tuning_.clutch_leave_rate * dt);
  trans_[0][0] = 1.0 - leave_clutch;
  for (int j = 1; j <= gears_; ++j)
    trans_[0][j] = leave_clutch * weight_[j] / (1.0 - weight_[0]);
  for (int i = 1; i <= gears_; ++i) {
    const double up = i < gears_ ? kToNeighbour * up_factor : 0.0;
    const double down = i > 1 ? kToNeighbour * down_factor : 0.0;
    const double total = kToClutch + up + down;
    const double leave = 1.0 - std::exp(-leave_rate_[i] * total * dt);
    trans_[i][i] = 1.0 - leave;
    trans_[i][0] = leave * kToClutch / total;
    if (i < gears_) trans_[i][i + 1] = leave * up / total;
    if (i > 1) trans_[i][i - 1] = leave * down / total;
  }
}

void SpeedSynthesizer::update_accel(double dt, double speed) noexcept {
  if (dt <= 0.0) return;
  const double a = std::clamp((speed - out_speed_) / dt, -tuning_.max_accel, tuning_.max_accel);
  const double k = 1.0 - std::exp(-dt / tuning_.accel_time);
  accel_ += k * (a - accel_);
}

// What GPS teaches about this engine and driver: the idle frequency (standing) and the frequencies run at
// in gear (moving). Running means with a bounded memory, so they follow a warming engine.
void SpeedSynthesizer::learn(double dt, double gps, double freq) noexcept {
  if (!std::isfinite(freq)) return;
  freq_max_ = std::max(freq_max_, freq);
  if (freq <= 0.0) return;
  const auto accumulate = [&](double& mean, double& var, double& count, double memory) {
    count = std::min(count + 1.0, memory / std::max(dt, 0.1));
    const double k = 1.0 / count;
    const double d = freq - mean;
    mean += k * d;
    var += k * (d * d * (1.0 - k) - var);
  };
  constexpr double kIdleMemory = 60.0;    // s
  constexpr double kDriveMemory = 600.0;  // s
  constexpr double kSureGear = 0.8;
  if (gps < tuning_.stationary_speed) {
    accumulate(idle_mean_, idle_var_, idle_count_, kIdleMemory);
  } else if (mode_ > 0 && prob_[mode_] > kSureGear && gps > 10.0 * tuning_.stationary_speed) {
    accumulate(drive_mean_, drive_var_, drive_count_, kDriveMemory);
  }
}

SynthOutput SpeedSynthesizer::gps_step(double dt, double gps, double freq) noexcept {
  compute_transitions(dt, freq);
  const bool have_freq = std::isfinite(freq);
  const double sf = have_freq ? freq_sigma(freq) : 0.0;
  for (int j = 0; j <= gears_; ++j) {
    double best = 0.0;
    for (int i = 0; i <= gears_; ++i)
      best = std::max(best, prob_[i] * trans_[i][j]);
    double evidence = 1.0;
    if (have_freq && gears_ > 0) {
      if (j == 0) {
        evidence = clutch_likelihood(freq);
      } else {
        const double s = sigma_v_ * sigma_v_ + theta_[j] * theta_[j] * sf * sf;
        evidence = gaussian(gps - theta_[j] * freq, s) * lugging(j, freq);
      }
    }
    next_p_[j] = best * evidence;
  }
  for (int j = 0; j <= gears_; ++j)
    prob_[j] = next_p_[j];
  normalise();
  speed_.fill(gps);
  var_.fill(sigma_v_ * sigma_v_);
  mode_ = map_mode();
  learn(dt, gps, freq);
  learn_shift(freq);
  update_accel(dt, gps);
  return {gps, gps >= tuning_.stationary_speed ? mode_ : 0, SpeedSource::kGps};
}

SynthOutput SpeedSynthesizer::engine_step(double dt, double freq) noexcept {
  const bool have_freq = std::isfinite(freq);
  if (have_freq) freq_max_ = std::max(freq_max_, freq);
  compute_transitions(dt, freq);
  // Declutched at (or without) idle the driver is braking to a stop: keep the recent deceleration,
  // within ordinary bounds. Declutched above idle is a shift: the car rolls on, slowing gently.
  const bool at_idle = !have_freq || (idle_count_ > 0.0 && freq < idle_mean_ + 3.0 * idle_sd());
  const double decel = at_idle ? std::clamp(-accel_, tuning_.stop_decel_min, tuning_.stop_decel_max)
                               : tuning_.shift_coast_decel;
  // In gear a driver who accelerates keeps accelerating (through shifts too), but braking may stop at any
  // moment: predict a share of the trend, with as much again as uncertainty.
  const double trend = (accel_ > 0.0 ? tuning_.trend_up : tuning_.trend_keep) * accel_ * dt;
  const double q = tuning_.accel_sigma * dt * tuning_.accel_sigma * dt;
  const double engage = tuning_.launch_accel * tuning_.launch_accel;
  const double sf = have_freq ? freq_sigma(freq) : 0.0;
  for (int j = 0; j <= gears_; ++j) {
    const double z = have_freq ? theta_[j] * freq : 0.0;
    const double r = theta_[j] * theta_[j] * sf * sf + 1e-6;
    const double lug = j > 0 && have_freq ? lugging(j, freq) : 1.0;
    double best = 0.0, best_v = speed_[j], best_var = var_[j];
    for (int i = 0; i <= gears_; ++i) {
      if (trans_[i][j] <= 0.0) continue;
      double v = 0.0, var = var_[i] + q;
      double evidence = 1.0;
      if (j == 0) {
        v = std::max(0.0, speed_[i] - decel * dt);
        evidence = have_freq ? clutch_likelihood(freq) : 1.0;
      } else {
        v = std::max(0.0, speed_[i] + trend);
        var += trend * trend;
        // Engaging a gear after clutch-out: the clutch slips until the engine matches the wheels, so the
        // speed the engine will show is uncertain by about what a launch gains in a second.
        if (i == 0) var += engage;
        evidence = have_freq ? gaussian(z - v, var + r) * lug : kLostGearLikelihood;
      }
      const double score = prob_[i] * trans_[i][j] * evidence;
      if (score > best) {
        best = score;
        best_v = v;
        best_var = std::min(var, kMaxSpeedVar);
      }
    }
    next_p_[j] = best;
    if (j > 0 && have_freq) {
      const double k = best_var / (best_var + r);
      best_v += k * (z - best_v);
      best_var *= 1.0 - k;
    }
    next_v_[j] = best_v;
    next_var_[j] = best_var;
  }
  for (int j = 0; j <= gears_; ++j) {
    prob_[j] = next_p_[j];
    speed_[j] = next_v_[j];
    var_[j] = next_var_[j];
  }
  normalise();
  const int previous_mode = mode_;
  mode_ = map_mode();
  if (mode_ == 0) {
    // Standing still is certain enough: do not let the guess drift while the car waits at a light.
    if (speed_[0] <= 0.0) var_[0] = std::min(var_[0], kInitialSpeedVar);
    // Braking to a stop goes on as it was; the trend of a shift (declutched above idle) fades.
    if (!at_idle) accel_ *= std::exp(-dt / tuning_.accel_time);
    return {speed_[0], 0, SpeedSource::kCoast};
  }
  // Moving off, the clutch slips: the car gains speed no faster than a brisk launch even though the engine
  // already turns at theta x freq.
  const double speed = std::min(speed_[mode_], out_speed_ + tuning_.launch_accel * dt);
  // A change of gear hypothesis moves the output by a step that is no acceleration of the car.
  if (mode_ == previous_mode && last_.source == SpeedSource::kEngine) update_accel(dt, speed);
  return {speed, mode_, SpeedSource::kEngine};
}

SynthOutput SpeedSynthesizer::step(double t, double gps_speed, double freq) noexcept {
  if (!std::isfinite(t)) return last_;
  double dt = started_ ? t - t_ : 0.0;
  if (dt < 0.0) dt = 0.0;
  if (!started_ || t > t_) t_ = t;
  started_ = true;
  if (dt > tuning_.max_gap) {
    for (int j = 0; j <= gears_; ++j)
      prob_[j] = weight_[j];
    var_.fill(kMaxSpeedVar);
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
