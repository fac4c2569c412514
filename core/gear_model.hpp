#pragma once
// The learned model: one scale factor theta_i = v / s per forward gear (paper eq. (3)), with the noise
// levels of eqs. (1)-(2). Immutable once built; the daemon swaps whole models atomically.
#include <algorithm>
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace gearpulse {

struct Gear {
  double theta = 0.0;      // (m/s)/Hz
  double weight = 0.0;     // alpha_i of eq. (6)
  double std_error = 0.0;  // standard error of theta from the observed information ("stderr" in JSON)
};

// m/s: the most first gear carries a car at the warm idle. Overall ratios of 12-16:1, tyres of 1.9-2 m
// round and an idle of 600-1000 rpm give 1.2-2.8 m/s at their extremes; the bound is the 2.6 m/s the
// synthesis' young ladders were decided with (docs/cold-start.md, "A ladder that lacks first gear"). A
// ladder whose lowest gear carries the car faster lacks first gear: the fit's ladder
// (docs/algorithms/estimator.md) and the synthesis' first_gear_idle_speed.
inline constexpr double kFirstGearIdleSpeed = 2.6;

struct GearModel {
  static constexpr int kVersion = 1;
  static constexpr std::size_t kMaxGears = 12;  // the most the estimator fits and the synthesis carries
  std::vector<Gear> gears;                      // ascending theta, constraint (5)
  double sigma_speed = 0.0;                     // sigma_v, m/s
  double sigma_freq = 0.0;                      // sigma_s, Hz
  std::size_t samples = 0;                      // samples used by the fit
  double log_likelihood = 0.0;
  // Fields beyond the contract's minimum; readers ignore what they do not know.
  double outlier_weight = 0.0;                      // beta of eq. (6)
  std::string method;                               // "auto" or "paper"
  std::string reason;                               // why no gear ladder was found (gears empty), else empty
  nlohmann::json extra = nlohmann::json::object();  // estimator-specific parameters (e.g. clutch-out density)

  [[nodiscard]] bool empty() const noexcept { return gears.empty(); }
};

// The rolling idle (extra.rolling_idle): the revs an engine is held at, above its standing idle, while the
// car rolls declutched. The fit (over a log) and the speed synthesis (under GPS, live) learn it by one rule:
// revs above the idle's spread and below kCeiling x idle that no gear explains, flat within kFlat for kSpan
// or more while the car, faster than kMinSpeed, slows.
namespace rolling_idle {
inline constexpr double kMinSpeed = 4.0;  // m/s: not a car braked to a stop or creeping on a slipping clutch
inline constexpr double kSpan = 1.5;      // s
inline constexpr double kFlat = 0.05;     // relative
inline constexpr double kCeiling = 1.6;   // x the standing idle
}  // namespace rolling_idle

// Braking declutched at idle (extra.idle_braking): declutched on the move with the engine at idle, the
// driver rolls or brakes to a stop. The fit (over a log) and the speed synthesis (under GPS, live) tell the
// state by one rule: revs below the rolling idle (or the standing one) plus kBandSds idle spreads, and
// measure its deceleration between speeds at least kMinGap apart (over less, the change of speed is mostly
// the receiver's noise).
namespace idle_braking {
inline constexpr double kBandSds = 2.5;  // idle spreads above the idle that are the engine idling
inline constexpr double kMinGap = 0.5;   // s
// A deceleration measured (m/s^2) as a habit: no car brakes harder than 4 m/s^2 in one, nor gains speed
// declutched.
[[nodiscard]] inline double clip(double accel) noexcept {
  return std::clamp(accel, -4.0, 1.0);
}
// What such a measurement weighs: the share of a second it covers, at most one.
[[nodiscard]] inline double weight(double dt) noexcept {
  return std::min(dt, 1.0);
}
}  // namespace idle_braking

// Spread of the idle frequency, bounded to 3-10 % of it so that a cold start's high idle or a single blip
// cannot make it cover the whole driving range (nor a perfectly steady idle make it vanish).
[[nodiscard]] inline double idle_spread(double idle, double sd) noexcept {
  return std::clamp(sd, 0.03 * idle, 0.1 * idle);
}

// JSON of `gearpulse fit --out` and of state_dir/model.json (docs/interfaces.md).
[[nodiscard]] nlohmann::json model_to_json(const GearModel& model);
// Throws std::invalid_argument with a readable message if the JSON is not a valid model
// (wrong version, non-positive or unordered theta, non-finite numbers).
[[nodiscard]] GearModel model_from_json(const nlohmann::json& json);
[[nodiscard]] std::string serialize_model(const GearModel& model);
[[nodiscard]] GearModel parse_model(std::string_view text);

}  // namespace gearpulse
