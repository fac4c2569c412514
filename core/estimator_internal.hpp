#pragma once
// Pieces shared by the estimator's translation units (not part of the public API).
#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "core/gear_model.hpp"
#include "core/launch_gears.hpp"
#include "core/mixture_likelihood.hpp"
#include "core/sample.hpp"

namespace gearpulse::detail {

inline constexpr double kStandingSpeed = 0.3;  // m/s: GPS speed below this is a car at rest
inline constexpr double kMovingSpeed = 1.0;    // m/s: samples above this tell a gear's ratio

struct IdleEstimate {
  double freq = 0.0;  // Hz, median of the engine frequency at rest
  double sd = 0.0;    // Hz, from the median absolute deviation
  std::size_t samples = 0;
};

// The engine's idle from the samples at rest, or nothing when fewer than min_samples of them.
[[nodiscard]] std::optional<IdleEstimate> estimate_idle(const MixtureData& data, std::size_t min_samples);

// The launches from rest in the log (core/fit_launch_gears.cpp): per count k of upshifts made before the car
// drives the ladder's lowest gear (`base_theta`; k = kMaxBelow: that many or more), how many launches made k.
struct LaunchCounts {
  double base_theta = 0.0;
  std::array<double, LaunchGears::kMaxBelow + 1> counts{};
  double launches = 0.0;
};
// Nothing where no launch was counted, the ladder has fewer than two gears, or the log reads its revs
// further apart than a launch holds first gear.
[[nodiscard]] std::optional<LaunchCounts> estimate_launch_gears(const MixtureData& data,
                                                                const GearModel& model,
                                                                const IdleEstimate& idle);

// How a driver uses each gear: the engine frequency over the samples on that gear's line, in log frequency
// (a gear used from 1200 to 2400 rpm spans the same width at any ratio).
struct GearRevs {
  double mean_log = 0.0;  // mean of ln(freq / Hz)
  double sd_log = 0.0;    // standard deviation of ln(freq)
  std::size_t samples = 0;
};

// The gear of `model` whose line (theta x freq = speed) the sample lies on, if any.
[[nodiscard]] std::optional<std::size_t> gear_on_line(const GearModel& model, double speed, double freq);

// One entry per gear of the fitted model; a gear no sample lies on has samples = 0.
[[nodiscard]] std::vector<GearRevs> estimate_gear_revs(const MixtureData& data, const GearModel& model);

// The engine's idle while the car rolls declutched (freq only; sd unused), when it is held above the
// standing `idle` on at least min_samples samples; nothing otherwise.
[[nodiscard]] std::optional<IdleEstimate> estimate_rolling_idle(const MixtureData& data,
                                                                const GearModel& model,
                                                                const IdleEstimate& idle,
                                                                std::size_t min_samples);

// The deceleration declutched at idle on the move (idle_braking in gear_model.hpp): the mean of the change of
// speed over successive pairs of samples kMinGap to kMaxDecelGap apart, the first faster than kMovingSpeed,
// both and all rows between with revs in the idle band (above `rolling`'s frequency when it is higher than
// the standing idle's), not both on one gear's line; each pair counts for the share of a second it covers,
// as under GPS.
struct DecelEstimate {
  double accel = 0.0;       // m/s^2
  double seconds = 0.0;     // s: the pairs' weight
  std::size_t samples = 0;  // pairs
};
inline constexpr double kMaxDecelGap = 3.0;  // s: a pair further apart may span a stop and a start
[[nodiscard]] std::optional<DecelEstimate> estimate_idle_braking(const MixtureData& data,
                                                                 const GearModel& model,
                                                                 const IdleEstimate& idle,
                                                                 const std::optional<IdleEstimate>& rolling);

// OBD loggers poll speed and rpm at different instants and repeat each value until its next poll: the
// log then pairs a fresh value of one with a held value of the other. holds_values tells such a log (most
// moving rows bring one new value of the two); interpolate_held replaces every held value by the straight
// line from its poll to the next one, when the two are at most kHeldSpan (sample.hpp) apart (a speed of 0
// stays: a car standing).
[[nodiscard]] bool holds_values(const MixtureData& data);
void interpolate_held(MixtureData& data);

// Why a log cannot hold a gear ladder (empty if it may): see estimator.cpp.
[[nodiscard]] std::string degenerate_log(const MixtureData& data);

// Paper mode: M = ratios.size() + 1, ratios top gear down (Table 2's c_i).
[[nodiscard]] GearModel fit_paper(const MixtureData& data, const std::vector<double>& ratios);

// Auto mode: gears = 0 chooses the count from the data, else exactly that many; single_gear as
// FitOptions::single_gear.
[[nodiscard]] GearModel fit_auto(const MixtureData& data, int gears, bool single_gear = false);

// Fills a GearModel from fitted parameters: log-likelihood, standard errors of theta from the inverse of
// the observed information (layout chooses which nuisance parameters are estimated alongside).
[[nodiscard]] GearModel finish_model(const MixtureData& data, const MixtureParams& p,
                                     const std::string& method, const GradientLayout& layout);

}  // namespace gearpulse::detail
