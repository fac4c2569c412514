#pragma once
// What a fit records beside the gear ladder (GearModel::extra, docs/interfaces.md) that the speed synthesis
// reads, as plain numbers. SpeedSynthesizer reads them once per model (set_model), so that rebuilding its
// ladder mid-drive (a gear seen under GPS, a gear predicted) walks no JSON on the step path.
#include <array>
#include <cstddef>
#include <limits>

#include "core/gear_model.hpp"
#include "core/launch_gears.hpp"

namespace gearpulse {

struct ModelExtras {
  static constexpr double kUnknown = std::numeric_limits<double>::quiet_NaN();
  // The revs the fit saw in one gear of the model (extra.revs[i]): ln(freq)'s mean and spread, the pairs.
  struct GearRevs {
    double mean_log = kUnknown, sd_log = kUnknown, samples = kUnknown;
  };

  double speed_lag = 0.0;                           // s: the fit's speeds against its revs (0 if absent)
  double idle_freq = kUnknown, idle_sd = kUnknown;  // Hz: the warm idle (extra.idle)
  double rolling_idle = kUnknown;                   // Hz: rolling declutched (extra.rolling_idle.freq)
  // m/s^2 declutched at idle, and the s of fixes it was measured on (extra.idle_braking).
  double idle_braking_accel = kUnknown, idle_braking_seconds = kUnknown;
  // Per gear of the model, in its order; all unknown unless extra.revs holds one entry per gear.
  std::array<GearRevs, GearModel::kMaxGears> revs{};
  bool has_revs = false;
  // The positive thetas of extra.lower_gears (gears below the ladder a ladder of more gears held), in the
  // order given, the first kMaxGears of them (a fit writes fewer).
  std::array<double, GearModel::kMaxGears> lower_gears{};
  std::size_t lower_count = 0;
  // The launches from rest in the fit's log (extra.launch_gears): per count k of upshifts before the
  // ladder's lowest gear (`launch_base`, 0 = none recorded), how many launches made k.
  double launch_base = 0.0;
  std::array<double, LaunchGears::kMaxBelow + 1> launch_counts{};
};

// The extras of `model` (none without one). Anything missing or malformed is left unknown: a hand-edited
// or older model.json still loads.
[[nodiscard]] ModelExtras read_model_extras(const GearModel* model) noexcept;

}  // namespace gearpulse
