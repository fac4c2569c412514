// The ladder the synthesis runs on (SpeedSynthesizer, core/speed_synth.hpp): loading it from the model and
// the gears that join it (synth_ladder_insert.cpp), changing it as gears are seen under GPS and launches
// counted, and the belief carried across a change of ladder.
#include <algorithm>
#include <array>
#include <cmath>
#include <span>

#include "core/estimator.hpp"
#include "core/speed_synth.hpp"
#include "core/synth_constants.hpp"

namespace gearpulse {
using namespace synth;
namespace {

constexpr double kDefaultClutchShare =
    0.15;  // declutched share when the model gives none (cf. beta, eq. (6))

}  // namespace

void SpeedSynthesizer::load_model() noexcept {
  const GearModel* model = model_.get();
  gears_ = model ? static_cast<int>(model->gears.size()) : 0;
  theta_.fill(0.0);
  theta_se_.fill(0.0);
  model_gear_.fill(0);
  weight_.fill(0.0);
  creep_.fill(0.0);
  for (int j = 1; j <= gears_; ++j) {
    const Gear& g = model->gears[static_cast<std::size_t>(j - 1)];
    theta_[j] = g.theta;  // its standard error stays 0: a fit's is well under the 1 % floor on a reading
    weight_[j] = std::max(g.weight, kMinGearShare);
    model_gear_[j] = j;
  }
  insert_seen_gears();
  insert_gap_gears();
  speed_lag_.set_prior(model && tuning_.speed_lag_prior > 0.0 ? extras_.speed_lag : 0.0);
  habits_.load_engine(extras_, tuning_);  // the warm idle, for the gears below the ladder
  // A model that does not say how many pairs it was fitted on (0) is taken as a mature one.
  young_idle_ = model && model->samples > 0 && static_cast<double>(model->samples) < tuning_.warm_fit_samples;
  insert_upper_gears();
  insert_fitted_lower_gears();
  insert_predicted_gears();
  double total = 0.0;
  for (int j = 1; j <= gears_; ++j)
    total += weight_[j];
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
    const double by_use = tuning_.dwell_by_use > 0.0 ? typical / weight_[j] : 1.0;
    leave_rate_[j] = std::clamp(by_use, 1.0 / kMaxRateFactor, kMaxRateFactor) / tuning_.gear_dwell;
  }
  sigma_v_ = std::max(model ? model->sigma_speed : 0.0, tuning_.min_speed_sigma);
  habits_.load_gear_revs(extras_, model_gear_, gears_);
  // A gear predicted above the model's top is run as that top gear is: cruising (insert_upper_gears).
  for (int j = 1, top = 0; j <= gears_; ++j) {
    if (model_gear_[j] > 0) top = j;
    for (int i = 0; i < upper_ && top > 0 && tuning_.top_gear_revs > 0.0; ++i)
      if (theta_[j] == upper_theta_[static_cast<std::size_t>(i)]) habits_.share_gear_revs(top, j);
  }
  sigma_s_ = model ? std::max(model->sigma_freq, 0.0) : 0.0;
}

bool SpeedSynthesizer::set_model(std::shared_ptr<const GearModel> model) noexcept {
  if (model && model->gears.size() > static_cast<std::size_t>(kMaxGears)) return false;
  model_ = std::move(model);
  extras_ = read_model_extras(model_.get());
  if (tuning_.fit_launch_gears > 0.0) launches_.seed(extras_.launch_base, extras_.launch_counts);
  read_top_gear_revs();
  std::array<double, kMaxGears> thetas{};
  seen_.forget_learned(thetas_of(model_.get(), thetas));
  change_ladder(true);
  return true;
}

// Revs at or below this are idling (Hz; 0 while no idle is known).
double SpeedSynthesizer::idle_ceiling() const noexcept {
  return habits_.idle_known() ? rolling_idle() + LaunchGears::kIdleSds * idle_sd() : 0.0;
}

// A gear seen under GPS that the model lacks (seen_) joins the ladder or leaves it.
void SpeedSynthesizer::observe_gear(double gps, double freq, double lag) noexcept {
  if (gears_ == 0 || model_ == nullptr) return;
  std::array<double, kMaxGears> thetas{};
  bool changed = seen_.observe(t_, gps, freq, idle_ceiling(), thetas_of(model_.get(), thetas), lag,
                               tuning_.creep_gears > 0.0 && habits_.lugged(freq, gears_, tuning_) >= 0.5);
  // The idle and the launches seen under GPS decide how many gears are missing below the ladder: the idle
  // may be learned, or fall as the engine warms, and a launch be counted, after the ladder was loaded.
  if (!changed && tuning_.predict_lower_gears > 0.0) {
    ModeArray theta{};
    changed = predict_lower_gears(predicted_ + 1, theta) != predicted_;
  }
  if (!changed && tuning_.predict_upper_gears > 0.0) {
    ModeArray theta{};
    changed = predict_upper_gears(theta) != predicted_above_;
  }
  if (changed) change_ladder(false);
}

// Under GPS, at every step: the launches from rest, counted by the upshifts they make before the filter holds
// the lowest gear of the ladder that is not predicted (the base; launch_gears.hpp). A launch's shifts show in
// its revs where every gear it holds is read at least once: an upshift lowers the revs by a gearbox step, and
// a gear passed between two readings deepens the fall by its own step (counted so), but a first gear passed
// unread leaves no fall at all (the revs climb from the idle straight into second). A launch holds first
// gear about kFirstGearHeld, so a launch whose revs above the idle are read further apart than that is not
// counted. A step reads the revs where they changed, or where the speed did not either: a logger writes a row
// when a value changes, a row for a new speed with the revs of its last poll (its rows, not its polls, are
// the steps), and a step that repeats both values comes from a feed that reads both at every step.
void SpeedSynthesizer::observe_launch(double gps, double freq, bool gps_new) noexcept {
  constexpr double kFirstGearHeld = LaunchGears::kFirstGearHeld;
  // The feed's reading interval: the mean over about the last ten readings (a logger's polls scatter within
  // its rounds, so one interval is no measure of them).
  constexpr double kReadingsMeant = 10.0;
  const bool revs_read = std::isfinite(freq) && (freq != launch_revs_ || gps == launch_speed_);
  launch_speed_ = gps;
  if (revs_read) {
    const double interval = t_ - launch_revs_t_;  // not finite at the first reading
    if (std::isfinite(interval))
      revs_interval_ =
          revs_interval_ > 0.0 ? revs_interval_ + (interval - revs_interval_) / kReadingsMeant : interval;
    launch_revs_ = freq;
    launch_revs_t_ = t_;
  }
  const bool read_apart = !(revs_interval_ > 0.0 && revs_interval_ <= kFirstGearHeld);
  const int base = predicted_ + 1;
  if (!std::isfinite(gps) || tuning_.launch_gears <= 0.0 || base > gears_ || read_apart) {
    launches_.abort();
    return;
  }
  const double step = base < gears_ ? std::log(theta_[base + 1] / theta_[base]) : 0.0;
  launches_.observe_revs(freq, step, idle_ceiling());
  if (!gps_new) return;
  constexpr double kConfident = 0.8;  // belief in the mode held for it to count
  const bool sure = is_gear(mode_) && mode_ >= base && prob_[mode_] >= kConfident;
  launches_.observe_fix(t_, gps < tuning_.stationary_speed, theta_[base], sure ? mode_ - base : -1);
}

// Loads the ladder of the model in use and the gears seen that it lacks, carrying the belief over from the
// ladder before. new_model: the model changed (else only the gears seen did, and every gear of the old
// ladder is still in the new one, or has left it).
void SpeedSynthesizer::change_ladder(bool new_model) noexcept {
  const int old_gears = gears_;
  const ModeArray old_theta = theta_, old_prob = prob_, old_age = age_;
  const TrackArray old_track = track_;
  load_model();
  if (!new_model) {
    // The same gears keep what was learned of them (their shift revs) under their new numbers.
    std::array<int, kModes> to{};  // new number of each old gear, 0 = gone
    for (int i = 1; i <= old_gears; ++i)
      for (int j = 1; j <= gears_; ++j)
        if (theta_[j] == old_theta[i]) to[i] = j;
    habits_.renumber_gears(to, old_gears);
  } else if (gears_ != old_gears) {
    habits_.forget_gear_shifts();  // shift revs learned per gear belong to the old ladder
  }
  // Carry the belief over: each old gear hands its probability to the new gear with the nearest theta
  // (in ratio) with its track, so a retrained model of the same car continues where it was.
  prob_.fill(0.0);
  prob_[0] = old_prob[0];
  track_[0] = old_track[0];
  age_.fill(0.0);
  age_[0] = old_age[0];
  pulled_.fill(0.0);  // per position of the old ladder
  for (int j = 1; j <= gears_; ++j)
    track_[j] = old_track[0];
  track_[launch_mode()] = old_track[old_gears + 1];
  age_[launch_mode()] = old_age[old_gears + 1];
  prob_[launch_mode()] = gears_ > 0 ? old_prob[old_gears + 1] : 0.0;
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
      track_[best] = old_track[i];
      age_[best] = old_age[i];
    }
  }
  if (gears_ == 0) {
    prob_.fill(0.0);
    prob_[0] = 1.0;
  } else if (old_gears == 0) {
    for (int j = 0; j <= gears_; ++j)
      prob_[j] = weight_[j];
  }
  normalise();
  mode_ = map_mode();
  // The last output (what step() repeats for a step it cannot take) names a gear of the new model.
  if (last_.gear > (model_ ? static_cast<int>(model_->gears.size()) : 0)) last_.gear = model_gear(mode_);
}

}  // namespace gearpulse