#include "daemon/learning_schedule.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/estimator.hpp"
#include "core/estimator_internal.hpp"

namespace gearpulse::daemon {

PairsSummary summarize_pairs(std::span<const Sample> pairs, const GearModel* model) {
  PairsSummary out;
  const auto moving = [](const Sample& s) { return s.has_speed() && s.speed > detail::kMovingSpeed; };
  for (std::size_t k = 1; k < pairs.size(); ++k) {
    const double dt = pairs[k].t - pairs[k - 1].t;
    if (moving(pairs[k]) && moving(pairs[k - 1]) && dt > 0.0)
      out.moving_time += std::min(dt, PairsSummary::kMaxStep);
  }
  const std::vector<double> steady = steady_log_ratios(pairs);
  out.largest_cluster = largest_gear_cluster(steady);
  if (!model || model->empty()) {
    out.new_gear_cluster = out.largest_cluster;
    return out;
  }
  out.model_gears = model->gears.size();
  std::vector<double> off;
  for (double r : steady) {
    const bool near = std::any_of(model->gears.begin(), model->gears.end(), [&](const Gear& g) {
      return std::abs(r - std::log(g.theta)) < 2.0 * kGearWindow;
    });
    if (!near) off.push_back(r);
  }
  out.new_gear_cluster = largest_gear_cluster(off);
  return out;
}

bool LearningSchedule::young(const PairsSummary& pairs, bool has_model) const noexcept {
  const double end = settings_.young_time;
  if (!(end > 0.0)) return false;
  // With a model: a restored store past the schedule leaves a loaded model to the interval rule, but the
  // fit at young_time is tried when the schedule has run up to it.
  return pairs.moving_time < end || (has_model && last_ && last_->moving_time < end);
}

std::optional<double> LearningSchedule::passed_refit(double moving_time) const noexcept {
  std::optional<double> passed;
  for (double at = settings_.first_refit; at < settings_.young_time && at <= moving_time; at *= 2.0)
    passed = at;
  if (settings_.young_time > 0.0 && moving_time >= settings_.young_time) passed = settings_.young_time;
  return passed;
}

std::optional<double> LearningSchedule::next_refit(double moving_time) const noexcept {
  if (!(settings_.young_time > 0.0) || !(settings_.first_refit > 0.0)) return std::nullopt;
  for (double at = settings_.first_refit; at < settings_.young_time; at *= 2.0)
    if (at > moving_time) return at;
  if (moving_time < settings_.young_time) return settings_.young_time;
  return std::nullopt;
}

bool LearningSchedule::due(const PairsSummary& pairs, bool has_model) const noexcept {
  if (!young(pairs, has_model)) return false;
  const std::optional<double> refit = passed_refit(pairs.moving_time);
  const bool refit_passed = refit && (!last_ || last_->moving_time < *refit);
  if (has_model) {
    // A gear the model lacks shows in fewer pairs than a first gear needs to be clear: the fit takes a gear
    // beside others on 5 samples. A quarter of cluster_pairs (10 by default) off the model's lines is a
    // try; after one that did not add the gear, a quarter more. A try against another ladder (or none)
    // says nothing of this cluster.
    const std::size_t step = std::max<std::size_t>(settings_.cluster_pairs / 4, 1);
    const std::size_t tried_new =
        last_ && last_->model_gears == pairs.model_gears ? last_->new_gear_cluster : 0;
    return refit_passed || (pairs.new_gear_cluster >= step && pairs.new_gear_cluster >= tried_new + step);
  }
  if (pairs.largest_cluster < settings_.cluster_pairs) return false;
  return !last_ || refit_passed ||
         pairs.largest_cluster >= last_->largest_cluster + settings_.cluster_pairs / 2;
}

void LearningSchedule::tried(const PairsSummary& pairs) noexcept {
  last_ = pairs;
}

}  // namespace gearpulse::daemon
