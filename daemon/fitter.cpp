#include "daemon/fitter.hpp"

#include <algorithm>
#include <cmath>
#include <stop_token>
#include <utility>
#include <vector>

#include "core/estimator.hpp"
#include "drivers/thread_slice_runner.hpp"

namespace gearpulse::daemon {

Retrainer::Fitter make_estimator_fitter() {
  // The default "auto" mode: no priors, the gear count comes from the data, as `gearpulse fit`, and one
  // gear accepted while the model is young; a large store's passes in two threads (the retrainer's thread
  // runs at the lowest priority, so the second core's share comes from idle time; the threads inherit it).
  return [](std::span<const Sample> samples, std::stop_token stop) -> GearModel {
    ThreadSliceRunner threads;
    FitOptions options;
    options.single_gear = true;
    options.parallel = &threads;
    options.stop = std::move(stop);
    return fit_gear_model(samples, options).model;
  };
}

GearModel keep_seen_gears(const GearModel& current, GearModel fitted, std::span<const Sample> pairs,
                          std::size_t judge_pairs) {
  if (current.empty() || fitted.empty()) return fitted;
  const std::vector<double> steady = steady_log_ratios(pairs);  // ascending
  const auto count = [&](double lo, double hi) {
    return static_cast<std::size_t>(std::lower_bound(steady.begin(), steady.end(), hi) -
                                    std::lower_bound(steady.begin(), steady.end(), lo));
  };
  constexpr double w = kGearWindow;
  const auto& revs_before = current.extra.find("revs");
  const bool have_revs = revs_before != current.extra.end() && revs_before->is_array() &&
                         revs_before->size() == current.gears.size();
  struct Kept {
    Gear gear;
    nlohmann::json revs;
  };
  std::vector<Kept> kept;
  for (std::size_t i = 0; i < current.gears.size(); ++i) {
    const Gear& g = current.gears[i];
    const double line = std::log(g.theta);
    const bool refitted = std::any_of(fitted.gears.begin(), fitted.gears.end(), [&](const Gear& f) {
      return std::abs(std::log(f.theta) - line) < 2.0 * w;
    });
    if (refitted) continue;
    const std::size_t on = count(line - w, line + w);
    const std::size_t beside = count(line - 3.0 * w, line - w) + count(line + w, line + 3.0 * w);
    if (on + beside >= judge_pairs && on < beside) continue;  // contradicted
    kept.push_back({g, have_revs ? (*revs_before)[i]
                                 : nlohmann::json{{"mean_log", 0.0}, {"sd_log", 0.0}, {"samples", 0}}});
  }
  if (kept.empty() || fitted.gears.size() + kept.size() > GearModel::kMaxGears) return fitted;
  double fitted_weight = 0.0, current_weight = 0.0;
  for (const Gear& g : fitted.gears)
    fitted_weight += g.weight;
  for (const Gear& g : current.gears)
    current_weight += g.weight;
  const double carry = current_weight > 0.0 ? fitted_weight / current_weight : 0.0;
  std::vector<Kept> merged;
  const auto revs_now = fitted.extra.find("revs");
  const bool fitted_revs =
      revs_now != fitted.extra.end() && revs_now->is_array() && revs_now->size() == fitted.gears.size();
  for (std::size_t i = 0; i < fitted.gears.size(); ++i)
    merged.push_back({fitted.gears[i], fitted_revs ? (*revs_now)[i] : nlohmann::json()});
  nlohmann::json kept_thetas = nlohmann::json::array();
  for (Kept& k : kept) {
    k.gear.weight *= carry;
    kept_thetas.push_back(k.gear.theta);
    merged.push_back(std::move(k));
  }
  std::sort(merged.begin(), merged.end(),
            [](const Kept& a, const Kept& b) { return a.gear.theta < b.gear.theta; });
  double total = 0.0;
  for (const Kept& k : merged)
    total += k.gear.weight;
  const double scale = total > 0.0 ? fitted_weight / total : 1.0;
  fitted.gears.clear();
  nlohmann::json revs = nlohmann::json::array();
  for (Kept& k : merged) {
    k.gear.weight *= scale;
    fitted.gears.push_back(k.gear);
    revs.push_back(std::move(k.revs));
  }
  if (fitted_revs) fitted.extra["revs"] = std::move(revs);
  fitted.extra[kKeptGears] = std::move(kept_thetas);
  // The fit's gears below its ladder (extra.lower_gears) are below the merged ladder's lowest or gone.
  if (const auto lower = fitted.extra.find("lower_gears"); lower != fitted.extra.end() && lower->is_array()) {
    const double below = fitted.gears.front().theta * std::exp(-2.0 * w);
    nlohmann::json still = nlohmann::json::array();
    for (const nlohmann::json& theta : *lower)
      if (theta.is_number() && theta.get<double>() < below) still.push_back(theta);
    if (still.empty())
      fitted.extra.erase(lower);
    else
      *lower = std::move(still);
  }
  return fitted;
}

bool one_gear_withdrawn(const GearModel& current, std::span<const Sample> pairs) {
  constexpr std::size_t kFitPairs = 30;  // moving samples the auto fit needs at least
  if (current.gears.size() != 1) return false;
  const double line = std::log(current.gears[0].theta);
  std::vector<double> off;  // ascending, as steady_log_ratios gives them
  for (double r : steady_log_ratios(pairs))
    if (std::abs(r - line) >= 2.0 * kGearWindow) off.push_back(r);
  return off.size() >= kFitPairs && 4 * largest_gear_cluster(off) < off.size();
}

}  // namespace gearpulse::daemon
