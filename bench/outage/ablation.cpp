// --ablate: the outage bench runs the workload once per rule of the synthesis with that rule absent
// (kRules), each rule a setting of SynthTuning fields (bench/synth_settings.hpp).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "bench/outage/outage.hpp"
#include "bench/outage_protocol.hpp"
#include "bench/synth_settings.hpp"
#include "core/speed_synth.hpp"

namespace gearpulse::bench::outage {

namespace {

// The rules of the daemon's synthesis, each with the setting at which it is absent. Physical quantities
// (accelerations, rates, noise floors) are not rules and are not switched off.
struct Rule {
  const char* name;
  const char* neutral;
};
constexpr Rule kRules[] = {
    {"hedge: output leans toward the contenders' speed", "hedge_share=0"},
    {"quantile: output mode above the belief's median", "output_quantile=0.5"},
    {"revs habit: steady revs scored by the gear's band", "revs_habit=0"},
    {"shift comfort: shifts toward the new gear's band", "shift_comfort=0"},
    {"lugging: no gear below the revs its driver holds it at", "lugging_first=1,lugging_other=1"},
    {"creeping: first gear exempt from lugging", "lugging_first=lugging_other"},
    {"launch gear: first gear left the sooner", "launch_gear_time=inf"},
    {"stop: slow declutched car brakes to rest", "stop_speed=0"},
    {"skip shifts", "skip_share=0"},
    {"second-gear launches", "launch_second=0"},
    {"climb: climbing revs cost the clutch", "climb_cost=0"},
    {"declutch caught within a long step", "declutch_time=0"},
    {"pulled engage: a declutch after a pull engages the gear above", "pulled_engage=0"},
    {"clutch follows the gear at hops", "clutch_track_share=0"},
    {"leave cap: gear hazard capped", "leave_cap=inf"},
    {"bite gap: biting clutch's spread", "bite_gap=0"},
    {"jump reopen: acceleration reopened", "jump_reopen=0"},
    {"downshift band: gear's revs band", "downshift_band=0"},
    {"dwell by use: rarely used gears left sooner", "dwell_by_use=0"},
    {"warm floor: idle down to the fit's warm idle", "warm_floor=0"},
    {"rolling idle: declutched revs held on the move", "rolling_idle=0"},
    {"per-gear shift revs", "gear_shift_points=0"},
    {"idle learned on the move", "idle_on_move=0"},
    {"pull transfer: acceleration scaled at a shift", "pull_transfer=0"},
    {"GPS acceleration clip", "gps_accel_clip=0"},
    {"lost gear cost: a gear fades without revs", "lost_gear_cost=0"},
    {"a tracker gap stepped over with the next reading", "gap_one_step=0"},
    {"launch fade: no move-off at speed", "launch_fade=0"},
    {"rest output: slow declutched output is 0", "rest_output=0"},
    {"seen gears: a steady ratio off the model is a gear", "seen_gear_fixes=inf"},
    {"creep gears: a gear seen only at lugged revs held there", "creep_gears=0"},
    {"idle braking: declutched at idle brakes as learned", "idle_braking=0"},
    {"idle braking prior: the fit's idle braking", "idle_braking_prior=0"},
    {"first gear at idle: a ladder too tall at idle lacks first", "first_gear_idle_speed=inf"},
    {"declutch brake spread: braking uncertain once declutched", "declutch_brake_spread=0"},
    {"declutch pull spread: a pull kept through revs falling too fast", "declutch_pull_spread=0"},
    {"lower gears: a ladder lacking first extended below", "predict_lower_gears=0"},
    {"fitted lower gears: the fit's gears below a ladder lacking first", "fitted_lower_gears=0"},
    {"fit launch gears: the fit's launches ask gears below its lowest", "fit_launch_gears=0"},
    {"upper gears: a young ladder extended above its top", "predict_upper_gears=0"},
    {"speed lag: a fix is the speed of a moment before", "speed_lag=0"},
    {"speed lag prior: the fit's speed lag until the drive's shows", "speed_lag_prior=0"},
    {"speed lag significance: the drive's best lag from its first fix", "speed_lag_significance=0"},
};

std::string figure(double med, double p95) {
  char b[40];
  std::snprintf(b, sizeof b, "%.2f / %.2f", med, p95);
  return b;
}

// A change of a figure: "0" when it is exactly unchanged, else signed to two decimals (+0.00 is a rise
// below 0.005).
std::string change(double med, double p95) {
  const auto one = [](double d) {
    char b[20];
    if (d == 0.0)
      std::snprintf(b, sizeof b, "0");
    else
      std::snprintf(b, sizeof b, "%+.2f", d);
    return std::string(b);
  };
  return one(med) + " / " + one(p95);
}

}  // namespace

// Runs the workload with `base` and once per rule with that rule absent; one markdown row per rule: the
// daemon's synthesis' per-outage distance error (median / p95, %) on every line of the set and its change
// against `base`, and how many of those figures grew.
void ablate(const Workload& w, const gearpulse::SynthTuning& base, const std::vector<std::string>& only,
            const Options& opt) {
  const auto summary = [&](const Outcome& o) {
    std::vector<std::pair<double, double>> f;
    for (const Results& r : o.all)
      f.emplace_back(quantile(r.dist[0], 0.5), quantile(r.dist[0], 0.95));
    return f;
  };
  std::printf(
      "\nAblation: per-outage distance error of the daemon's synthesis, median / p95 %%\n\n| rule | absent "
      "at |");
  for (const Line& l : w.lines)
    std::printf(" %s |", l.label.c_str());
  std::printf(" figures worse |\n|---|---|");
  for (std::size_t l = 0; l < w.lines.size(); ++l)
    std::printf("---|");
  std::printf("---|\n");
  const auto defaults = summary(evaluate(w, base, opt));
  std::printf("| defaults | |");
  for (const auto& [med, p95] : defaults)
    std::printf(" %s |", figure(med, p95).c_str());
  std::printf(" |\n");
  std::fflush(stdout);
  for (const Rule& rule : kRules) {
    if (!only.empty() && std::find(only.begin(), only.end(), rule.neutral) == only.end()) continue;
    gearpulse::SynthTuning t = base;
    if (!apply_settings(t, rule.neutral)) continue;
    const auto f = summary(evaluate(w, t, opt));
    int worse = 0;
    std::printf("| %s | `%s` |", rule.name, rule.neutral);
    for (std::size_t l = 0; l < f.size(); ++l) {
      const double dm = f[l].first - defaults[l].first, dp = f[l].second - defaults[l].second;
      worse += (dm > 0.0 ? 1 : 0) + (dp > 0.0 ? 1 : 0);
      std::printf(" %s |", change(dm, dp).c_str());
    }
    std::printf(" %d of %zu |\n", worse, 2 * f.size());
    std::fflush(stdout);
  }
}

}  // namespace gearpulse::bench::outage
