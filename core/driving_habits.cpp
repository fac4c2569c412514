#include "core/driving_habits.hpp"

#include <algorithm>

namespace gearpulse {
namespace {

// The priors, each worth a few observations, so that the car's own driving outweighs them within minutes.
// Everyday driving: accelerations of 0.5-1.5 m/s^2 rms; worth 30 s of fixes.
constexpr double kAccelSd = 1.0, kAccelWeight = 30.0;
// Declutched and moving a car slows by rolling drag (about 0.2 m/s^2) plus whatever the brakes add; worth
// 10 s of fixes.
constexpr double kCoastAccel = -0.5, kCoastSd = 1.0, kCoastWeight = 10.0;
// A gear is held about 10 s in mixed driving (a shift every few seconds moving off, minutes on a highway);
// worth one gear left.
constexpr double kGearDwell = 10.0, kDwellWeight = 1.0;
// Where a gear is left for: mostly the next one up or down or the clutch (coasting, stopping); skips are
// rarer and mostly downward (braking from speed). Worth 4 shifts.
constexpr std::array<double, kShiftKinds> kShiftPrior = {0.35, 0.2, 0.02, 0.08, 0.35};
constexpr double kShiftWeight = 4.0;
// Declutched while moving, a shift's clutch is back in within about a second; worth two shifts.
constexpr double kEngageTime = 1.0, kEngageWeight = 2.0;
// Standing, a stop lasts tens of seconds; worth one stop.
constexpr double kStopTime = 20.0, kStopWeight = 1.0;
// Moving off, the clutch bites within one to two seconds, the car gaining about 1.5 m/s^2 (a brisk
// everyday launch; 3 m/s^2 is hard); worth two launches.
constexpr double kBiteTime = 1.5, kBiteWeight = 2.0;
constexpr double kLaunchAccel = 1.5, kLaunchSd = 0.8, kLaunchWeight = 3.0;
// A gear above first at idle revs: at most a second in twenty; worth 20 s in gear.
constexpr double kLugging = 0.05, kLuggingWeight = 20.0;
// A speed below this (m/s) is standing; above kMoving the car rolls (declutched coasting is learned there).
constexpr double kStanding = 0.3, kMoving = 2.0;

}  // namespace

void HabitLearner::Moments::add(double x, double w) noexcept {
  n += w;
  const double d = x - mean;
  mean += d * w / n;
  m2 += w * d * (x - mean);
}

void HabitLearner::Moments::add_recent(double x, double w, double memory) noexcept {
  const double keep = std::exp(-w / memory);
  n *= keep;
  m2 *= keep;
  add(x, w);
}

void HabitLearner::reset() noexcept {
  accel_ = {kAccelWeight, 0.0, kAccelWeight * kAccelSd * kAccelSd};
  coast_ = {kCoastWeight, kCoastAccel, kCoastWeight * kCoastSd * kCoastSd};
  idle_ = {};
  revs_ = {};
  gear_revs_.fill({});
  launch_accel_ = {kLaunchWeight, kLaunchAccel, kLaunchWeight * kLaunchSd * kLaunchSd};
  launch_time_ = kBiteTime * kBiteWeight;
  upper_gear_time_ = kLuggingWeight;
  lugging_time_ = kLugging * kLuggingWeight;
  bites_ = kBiteWeight;
  gear_time_.fill(kGearDwell * kDwellWeight);
  gear_leaves_.fill(kDwellWeight);
  for (int k = 0; k < kShiftKinds; ++k)
    shift_count_[k] = kShiftPrior[k] * kShiftWeight;
  moving_declutched_time_ = kEngageTime * kEngageWeight;
  moving_engages_ = kEngageWeight;
  standing_time_ = kStopTime * kStopWeight;
  launches_ = kStopWeight;
  last_sure_ = -1;
  last_standing_ = false;
  freq_max_ = 0.0;
  update();
}

void HabitLearner::seed_from(const GearModel& model) noexcept {
  const nlohmann::json& extra = model.extra;
  if (!extra.is_object()) return;
  // The fit's idle and revs stand for up to a minute of observations until the car's own replace them.
  constexpr double kSeedWeight = 60.0;
  try {
    if (const auto it = extra.find("idle"); it != extra.end() && it->is_object() && idle_.n < kSeedWeight) {
      const double f = it->value("freq", NAN), sd = it->value("sd", NAN);
      if (std::isfinite(f) && f > 0.0 && std::isfinite(sd) && sd >= 0.0)
        idle_ = {kSeedWeight, f, kSeedWeight * sd * sd};
    }
    if (const auto it = extra.find("revs"); it != extra.end() && it->is_array() && revs_.n < kSeedWeight) {
      Moments pooled;
      std::size_t gear = 0;
      for (const auto& r : *it) {
        ++gear;
        if (!r.is_object()) continue;
        const double m = r.value("mean_log", NAN), sd = r.value("sd_log", NAN), n = r.value("samples", 0.0);
        if (!std::isfinite(m) || !std::isfinite(sd) || !(n > 0.0)) continue;
        const double w = std::min(n, kSeedWeight);
        if (gear < gear_revs_.size()) gear_revs_[gear] = {w, m, w * sd * sd};
        // Pooling gear by gear: the within-gear spread plus the spread of the gears' means.
        const double before = pooled.mean;
        pooled.n += w;
        pooled.mean += (m - before) * w / pooled.n;
        pooled.m2 += w * sd * sd + w * (m - before) * (m - pooled.mean);
      }
      if (pooled.n > 0.0) revs_ = pooled;
    }
  } catch (...) {
    // A malformed extra is ignored (model_from_json validated what the synthesis must have).
  }
  update();
}

void HabitLearner::observe(double dt, int mode, int launch, double speed, double freq,
                           double accel) noexcept {
  if (!(dt > 0.0) || !std::isfinite(speed)) return;
  const bool standing = speed < kStanding;
  const bool moving = speed > kMoving;
  if (std::isfinite(freq) && freq > 0.0) freq_max_ = std::max(freq_max_, freq);
  if (mode < 0) {
    update();
    return;
  }
  const bool gear = mode > 0 && mode != launch;
  // Coasting is learned at idle revs: a shift's declutch (revs on their way to the next gear) is over in a
  // second and says little of how the car slows when it rolls.
  const bool at_idle =
      !idle_.n || (std::isfinite(freq) &&
                   std::abs(freq - idle_.mean) < 3.0 * idle_spread(idle_.mean, std::sqrt(idle_.var())));
  if (std::isfinite(accel)) {
    if (gear && moving) accel_.add(accel, dt);
    if (mode == 0 && moving && at_idle) coast_.add(accel, dt);
    if (mode == launch) launch_accel_.add(accel, dt);
  }
  // The idle drifts (a cold engine settles over minutes, the air conditioning raises it): the last minute
  // of standing counts.
  constexpr double kIdleMemory = 60.0;  // s
  if (mode == 0 && standing && std::isfinite(freq) && freq > 0.0) idle_.add_recent(freq, dt, kIdleMemory);
  if (gear && mode > 1 && std::isfinite(freq) && idle_.n > 0.0) {
    upper_gear_time_ += dt;
    if (freq < idle_.mean + 2.0 * idle_spread(idle_.mean, std::sqrt(idle_.var()))) lugging_time_ += dt;
  }
  if (gear && moving && std::isfinite(freq) && freq > 0.0) {
    revs_.add(std::log(freq), dt);
    gear_revs_[static_cast<std::size_t>(mode)].add(std::log(freq), dt);
  }

  // Time in modes, and where a mode was left for (the next mode the learner is sure of).
  if (last_sure_ >= 0 && mode != last_sure_) {
    if (last_sure_ == launch) {
      bites_ += mode > 0 ? 1.0 : 0.0;
    } else if (mode == launch) {
      launches_ += 1.0;
    } else if (last_sure_ > 0) {
      gear_leaves_[static_cast<std::size_t>(last_sure_)] += 1.0;
      const int step = mode - last_sure_;
      const ShiftKind kind = mode == 0    ? ShiftKind::kDeclutch
                             : step == 1  ? ShiftKind::kUp
                             : step == -1 ? ShiftKind::kDown
                             : step > 1   ? ShiftKind::kSkipUp
                                          : ShiftKind::kSkipDown;
      shift_count_[static_cast<std::size_t>(kind)] += 1.0;
    } else if (!last_standing_) {
      moving_engages_ += 1.0;
    }
  }
  if (mode == launch)
    launch_time_ += dt;
  else if (mode > 0)
    gear_time_[static_cast<std::size_t>(mode)] += dt;
  else if (standing)
    standing_time_ += dt;
  else
    moving_declutched_time_ += dt;
  last_sure_ = mode;
  last_standing_ = standing;
  update();
}

void HabitLearner::update() noexcept {
  DrivingHabits& h = habits_;
  h.accel_sd = std::sqrt(accel_.m2 / accel_.n + accel_.mean * accel_.mean);
  h.coast_accel = std::min(coast_.mean, 0.0);  // declutched, nothing drives the car
  h.coast_sd = std::sqrt(coast_.var());
  h.idle = idle_.n > 0.0 ? idle_.mean : NAN;
  h.idle_sd = idle_.n > 0.0 ? idle_spread(idle_.mean, std::sqrt(idle_.var())) : NAN;
  h.revs_mean = revs_.n > 0.0 ? revs_.mean : NAN;
  // A driver's band spans at least a fifth either way (one gear's step), however steady his driving.
  h.revs_sd = revs_.n > 0.0 ? std::max(std::sqrt(revs_.var()), 0.2) : 0.35;
  // A gear's own band, shrunk toward the pooled one by 10 s worth of it (a gear seen for seconds only).
  constexpr double kShrink = 10.0;
  for (std::size_t g = 1; g < gear_revs_.size(); ++g) {
    const Moments& m = gear_revs_[g];
    if (!std::isfinite(h.revs_mean)) {
      h.gear_revs_mean[g] = NAN;
      continue;
    }
    const double n = m.n + kShrink;
    h.gear_revs_mean[g] = (m.n * m.mean + kShrink * h.revs_mean) / n;
    h.gear_revs_sd[g] = std::max(std::sqrt((m.m2 + kShrink * h.revs_sd * h.revs_sd) / n), 0.15);
  }
  h.lugging = lugging_time_ / upper_gear_time_;
  h.freq_max = freq_max_;
  for (int g = 1; g < kMaxModes; ++g)
    h.leave_rate[static_cast<std::size_t>(g)] =
        gear_leaves_[static_cast<std::size_t>(g)] / gear_time_[static_cast<std::size_t>(g)];
  double total = 0.0;
  for (double c : shift_count_)
    total += c;
  for (int k = 0; k < kShiftKinds; ++k)
    h.shift_share[static_cast<std::size_t>(k)] = shift_count_[k] / total;
  h.engage_rate = moving_engages_ / moving_declutched_time_;
  h.launch_rate = launches_ / standing_time_;
  h.bite_rate = bites_ / launch_time_;
  h.launch_accel = std::max(launch_accel_.mean, 0.0);
  h.launch_sd = std::sqrt(launch_accel_.var());
}

}  // namespace gearpulse
