#include "core/synth_output.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "core/synth_tuning.hpp"

namespace gearpulse {

double contended_speed(std::span<const double> prob, std::span<const double> speed) noexcept {
  double sum = 0.0, weights = 0.0;
  for (std::size_t j = 0; j < prob.size() && j < speed.size(); ++j) {
    const double w = prob[j] * prob[j];
    sum += w * speed[j];
    weights += w;
  }
  return weights > 0.0 ? sum / weights : 0.0;
}

int belief_quantile_mode(std::span<const double> prob, std::span<const double> speed, double q) noexcept {
  constexpr std::size_t kMost = 16;
  const std::size_t n = std::min({prob.size(), speed.size(), kMost});
  if (n == 0) return -1;
  std::size_t lead = 0;
  double total = 0.0;
  for (std::size_t j = 0; j < n; ++j) {
    total += prob[j];
    if (prob[j] > prob[lead]) lead = j;
  }
  if (!(total > 0.0)) return static_cast<int>(lead);
  if (prob[lead] >= std::max(q, 1.0 - q) * total) return static_cast<int>(lead);
  std::array<std::size_t, kMost> order{};
  for (std::size_t j = 0; j < n; ++j)
    order[j] = j;
  // Slowest first; among equal speeds the most probable first, so that it names its group.
  std::sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(n), [&](std::size_t a, std::size_t b) {
    return speed[a] < speed[b] || (speed[a] == speed[b] && prob[a] > prob[b]);
  });
  double below = 0.0;
  std::size_t group = 0;  // first (most probable) member of the current group of equal speeds
  for (std::size_t k = 0; k < n; ++k) {
    if (k == 0 || speed[order[k]] != speed[order[group]]) group = k;
    below += prob[order[k]];
    if (below >= q * total) return static_cast<int>(order[group]);
  }
  return static_cast<int>(order[group]);
}

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

SynthOutput SynthOutputPolicy::outage(std::span<const double> prob, std::span<const double> speed,
                                      std::span<const double> speed_var, int gears,
                                      std::span<const int> model_gear, int map_mode,
                                      const SynthTuning& tuning) noexcept {
  const auto modes = std::min({prob.size(), speed.size(), speed_var.size()});
  const auto is_gear = [&](std::size_t j) { return j >= 1 && j <= static_cast<std::size_t>(gears); };
  // Each mode's speed as its history has it (which orders the belief for the output's mode) and as the
  // output counts it: a declutched or moving-off history slower than walking pace is at rest.
  std::array<double, kMaxModes> mode_speed{};
  const std::size_t n = std::min(modes, kMaxModes);
  for (std::size_t j = 0; j < n; ++j) {
    const double v = std::max(speed[j], 0.0);
    mode_speed[j] = is_gear(j) || v >= tuning.stationary_speed || tuning.rest_output <= 0.0 ? v : 0.0;
  }
  int out = belief_quantile_mode(prob.first(n), speed.first(n), tuning.output_quantile);
  if (out < 0) out = map_mode;
  const auto o = static_cast<std::size_t>(out);
  const double v = (1.0 - tuning.hedge_share) * std::max(speed[o], 0.0) +
                   tuning.hedge_share * contended_speed(prob.first(n), {mode_speed.data(), n});
  double spread = 0.0, total = 0.0;
  for (std::size_t j = 0; j < n; ++j) {
    const double d = mode_speed[j] - v;
    spread += prob[j] * (std::max(speed_var[j], 0.0) + d * d);
    total += prob[j];
  }
  const double sd = total > 0.0 ? std::sqrt(spread / total) : 0.0;
  if (is_gear(o)) return {v, o < model_gear.size() ? model_gear[o] : 0, SpeedSource::kEngine, sd};
  // Declutched and slower than walking pace is at rest: a mixture of rest and a hesitant move-off must not
  // trickle pulses.
  return {v < tuning.stationary_speed && tuning.rest_output > 0.0 ? 0.0 : v, 0, SpeedSource::kCoast, sd};
}

SynthOutput SynthOutputPolicy::hold(double t, double gps, const SynthTuning& tuning) const noexcept {
  if (std::isfinite(gps)) return {gps, 0, SpeedSource::kGps};
  if (held_speed_ < 0.0) return {0.0, 0, SpeedSource::kNone};
  const double coasted = std::max(0.0, t - held_t_ - tuning.hold_time);
  const double v = std::max(0.0, held_speed_ + tuning.coast_accel * coasted);
  return {v < tuning.stationary_speed ? 0.0 : v, 0, SpeedSource::kCoast};
}

}  // namespace gearpulse
