// The synthesis' tuning in the outage bench: --synth KEY=VALUE sets a SynthTuning field; --ablate runs the
// workload once per rule of the synthesis with that rule absent (kRules).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "bench/outage/outage.hpp"
#include "bench/outage_protocol.hpp"
#include "core/speed_synth.hpp"

namespace gearpulse::bench::outage {

namespace {

// A SynthTuning field by its name, for --synth and the rules' settings.
struct Field {
  const char* name;
  double gearpulse::SynthTuning::*member;
};
#define GEARPULSE_FIELD(name)            \
  Field {                                \
#name, &gearpulse::SynthTuning::name \
  }
constexpr Field kFields[] = {
    GEARPULSE_FIELD(accel_sigma),
    GEARPULSE_FIELD(accel_time),
    GEARPULSE_FIELD(coast_accel),
    GEARPULSE_FIELD(coast_sigma),
    GEARPULSE_FIELD(coast_time),
    GEARPULSE_FIELD(stop_speed),
    GEARPULSE_FIELD(stop_accel),
    GEARPULSE_FIELD(launch_accel),
    GEARPULSE_FIELD(launch_sigma),
    GEARPULSE_FIELD(brake_rate),
    GEARPULSE_FIELD(brake_sigma),
    GEARPULSE_FIELD(gear_dwell),
    GEARPULSE_FIELD(engage_rate),
    GEARPULSE_FIELD(launch_rate),
    GEARPULSE_FIELD(bite_rate),
    GEARPULSE_FIELD(launch_second),
    GEARPULSE_FIELD(skip_share),
    GEARPULSE_FIELD(evidence_time),
    GEARPULSE_FIELD(idle_weight),
    GEARPULSE_FIELD(lugging_first),
    GEARPULSE_FIELD(lugging_other),
    GEARPULSE_FIELD(launch_gear_time),
    GEARPULSE_FIELD(revs_habit),
    GEARPULSE_FIELD(shift_comfort),
    GEARPULSE_FIELD(min_speed_sigma),
    GEARPULSE_FIELD(min_freq_rel),
    GEARPULSE_FIELD(stationary_speed),
    GEARPULSE_FIELD(max_gap),
    GEARPULSE_FIELD(hold_time),
    GEARPULSE_FIELD(hedge_share),
    GEARPULSE_FIELD(output_quantile),
    GEARPULSE_FIELD(climb_cost),
    GEARPULSE_FIELD(declutch_time),
    GEARPULSE_FIELD(clutch_track_share),
    GEARPULSE_FIELD(leave_cap),
    GEARPULSE_FIELD(bite_gap),
    GEARPULSE_FIELD(jump_reopen),
    GEARPULSE_FIELD(downshift_band),
    GEARPULSE_FIELD(dwell_by_use),
    GEARPULSE_FIELD(warm_floor),
    GEARPULSE_FIELD(rolling_idle),
    GEARPULSE_FIELD(gear_shift_points),
    GEARPULSE_FIELD(idle_on_move),
    GEARPULSE_FIELD(pull_transfer),
    GEARPULSE_FIELD(gps_accel_clip),
    GEARPULSE_FIELD(lost_gear_cost),
    GEARPULSE_FIELD(launch_fade),
    GEARPULSE_FIELD(rest_output),
    GEARPULSE_FIELD(seen_gear_fixes),
    GEARPULSE_FIELD(idle_braking),
    GEARPULSE_FIELD(idle_braking_prior),
    GEARPULSE_FIELD(first_gear_idle_speed),
    GEARPULSE_FIELD(declutch_brake_spread),
    GEARPULSE_FIELD(predict_lower_gears),
    GEARPULSE_FIELD(fitted_lower_gears),
    GEARPULSE_FIELD(fill_ladder_gaps),
    GEARPULSE_FIELD(launch_gears),
    GEARPULSE_FIELD(speed_lag),
    GEARPULSE_FIELD(speed_lag_prior),
    GEARPULSE_FIELD(speed_lag_significance),
};
#undef GEARPULSE_FIELD

const Field* field_named(std::string_view name) {
  for (const Field& f : kFields)
    if (name == f.name) return &f;
  return nullptr;
}

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
    {"launch fade: no move-off at speed", "launch_fade=0"},
    {"rest output: slow declutched output is 0", "rest_output=0"},
    {"seen gears: a steady ratio off the model is a gear", "seen_gear_fixes=inf"},
    {"idle braking: declutched at idle brakes as learned", "idle_braking=0"},
    {"idle braking prior: the fit's idle braking", "idle_braking_prior=0"},
    {"first gear at idle: a ladder too tall at idle lacks first", "first_gear_idle_speed=inf"},
    {"declutch brake spread: braking uncertain once declutched", "declutch_brake_spread=0"},
    {"lower gears: a ladder lacking first extended below", "predict_lower_gears=0"},
    {"fitted lower gears: the fit's gears below a ladder lacking first", "fitted_lower_gears=0"},
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

// Applies "KEY=VALUE[,KEY=VALUE...]": VALUE is a number ("inf" too) or another field's name (its value).
bool apply_settings(gearpulse::SynthTuning& t, std::string_view settings) {
  while (!settings.empty()) {
    const std::size_t comma = settings.find(',');
    const std::string_view one = settings.substr(0, comma);
    settings = comma == std::string_view::npos ? std::string_view{} : settings.substr(comma + 1);
    const std::size_t eq = one.find('=');
    const Field* key = eq == std::string_view::npos ? nullptr : field_named(one.substr(0, eq));
    if (key == nullptr) return false;
    const std::string value(one.substr(eq + 1));
    if (const Field* other = field_named(value)) {
      t.*(key->member) = t.*(other->member);
      continue;
    }
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    if (value.empty() || *end != '\0') return false;
    t.*(key->member) = v;
  }
  return true;
}

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
