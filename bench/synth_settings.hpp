// SynthTuning fields by name, for the benches' --synth KEY=VALUE and the outage bench's ablation rules.
#pragma once

#include <cstdlib>
#include <string>
#include <string_view>

#include "core/speed_synth.hpp"

namespace gearpulse::bench {

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
    GEARPULSE_FIELD(pulled_engage),
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
    GEARPULSE_FIELD(gap_one_step),
    GEARPULSE_FIELD(launch_fade),
    GEARPULSE_FIELD(rest_output),
    GEARPULSE_FIELD(seen_gear_fixes),
    GEARPULSE_FIELD(creep_gears),
    GEARPULSE_FIELD(idle_braking),
    GEARPULSE_FIELD(idle_braking_prior),
    GEARPULSE_FIELD(first_gear_idle_speed),
    GEARPULSE_FIELD(declutch_brake_spread),
    GEARPULSE_FIELD(declutch_pull_spread),
    GEARPULSE_FIELD(predict_lower_gears),
    GEARPULSE_FIELD(fitted_lower_gears),
    GEARPULSE_FIELD(fill_ladder_gaps),
    GEARPULSE_FIELD(fill_top_step),
    GEARPULSE_FIELD(gap_gear_share),
    GEARPULSE_FIELD(gap_step_growth),
    GEARPULSE_FIELD(launch_gears),
    GEARPULSE_FIELD(fit_launch_gears),
    GEARPULSE_FIELD(predict_upper_gears),
    GEARPULSE_FIELD(top_gear_idle_speed),
    GEARPULSE_FIELD(top_gear_revs),
    GEARPULSE_FIELD(upper_gear_samples),
    GEARPULSE_FIELD(cold_idle_ratio),
    GEARPULSE_FIELD(warm_fit_samples),
    GEARPULSE_FIELD(speed_lag),
    GEARPULSE_FIELD(speed_lag_prior),
    GEARPULSE_FIELD(speed_lag_significance),
};
#undef GEARPULSE_FIELD

inline const Field* field_named(std::string_view name) {
  for (const Field& f : kFields)
    if (name == f.name) return &f;
  return nullptr;
}

// Applies "KEY=VALUE[,KEY=VALUE...]": VALUE is a number ("inf" too) or another field's name (its value).
inline bool apply_settings(gearpulse::SynthTuning& t, std::string_view settings) {
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

}  // namespace gearpulse::bench
