#pragma once
// Gear-scale estimation from unlabelled (speed, frequency) samples.
// "paper" mode: the ML estimator of eqs. (6)-(9) with the initialisation (11)-(16) and Table 2 constants.
// "auto" mode (default): no priors; gear count, weights and the clutch-out density come from the data.
#include <cmath>
#include <span>
#include <stdexcept>
#include <stop_token>
#include <string>
#include <vector>

#include "core/gear_model.hpp"
#include "core/sample.hpp"
#include "core/slice_runner.hpp"

namespace gearpulse {

struct FitOptions {
  int gears = 0;               // 0 = choose from the data; N = exactly N gears
  std::vector<double> ratios;  // paper's c_i, top gear down as Table 2 (c1 ~ theta_M/theta_{M-1});
                               // non-empty selects the paper's method with M = ratios.size() + 1
  // Auto mode with gears = 0: where no ladder of two or more gears passes, accept one gear (a model still
  // learning that has seen the car in one gear so far), if its window holds at least half of the steady
  // moving pairs and fewer than 30 steady pairs lie outside it (more steady driving elsewhere is a gear the
  // ladder should show, or a continuum, as from a CVT below the ratio it holds at cruise).
  bool single_gear = false;
  SliceRunner* parallel = nullptr;  // runs the passes over a large log in slices; null: on this thread
  // A stop requested here ends the fit at its next pass over the data (a few milliseconds on a week of
  // pairs) with FitCancelled: the daemon's retrainer stops at once rather than when the fit is done.
  std::stop_token stop;
};

// Thrown by fit_gear_model when FitOptions::stop was requested.
class FitCancelled : public std::runtime_error {
 public:
  FitCancelled() : std::runtime_error("fit cancelled") {}
};

struct FitResult {
  GearModel model;  // gears empty when no discrete ladder exists; model.reason says why
};

// Samples lacking speed or frequency are ignored. Throws std::invalid_argument for unusable options.
[[nodiscard]] FitResult fit_gear_model(std::span<const Sample> samples, const FitOptions& options);

// Half the width of a window of log(speed / frequency) that never holds two gears: half the smallest
// step between adjacent gears the fit accepts (a factor of 1.06).
inline constexpr double kGearWindow = 0.029;

// Whether two log(speed / frequency) readings next to each other in time, the later at `speed` (m/s), show
// one gear: within 3 % (the revs' jitter and the tracker's), widened at low speed, where a few tenths of
// m/s of speed error (GPS noise, integer km/h) move the ratio. The steady-pair rule of the auto fit and of
// the gears the synthesis measures under GPS.
[[nodiscard]] inline bool steady_ratios_agree(double log_ratio, double neighbour, double speed) noexcept {
  return std::abs(log_ratio - neighbour) < 0.03 + 0.3 / speed;
}

// log(speed / frequency) of the moving samples in gear, ascending: those whose ratio agrees with a time
// neighbour's (the rule the auto fit reads gear clusters with; shifts and clutch slip give isolated ratios).
[[nodiscard]] std::vector<double> steady_log_ratios(std::span<const Sample> samples);
// The most of those ratios (sorted) that lie within one window of width 2 x kGearWindow: the pairs of the
// clearest single gear.
[[nodiscard]] std::size_t largest_gear_cluster(std::span<const double> sorted_log_ratios);

// One log read twice: speed over ground from GPS (what the daemon sees live) and the car's own wheel speed
// (OBD), rows matched by t.
struct TwoSpeedLog {
  std::span<const Sample> gps;
  std::span<const Sample> wheel;
};

// The ladder from the wheel speed, its scale from GPS. The gearbox ties the engine to the wheels: the
// wheel speed shows a launch as it happens, where GPS Doppler lags by about a second and is coarse at a
// crawl (first gear then smears into a continuum), but it reads the speedometer's calibration (tyre wear,
// a maker's margin) and the logger's rounding (whole mph or km/h, often cut down). So the wheel speed is
// mapped onto GPS speed by the line through the instants where both read a moving car (Theil-Sen), and
// the model is fitted on it (model extra.speed_scale gives the line). The model is the fit on the GPS
// speed alone when fewer than 30 such instants exist, when that fit finds no ladder (an automatic's
// lock-up can leave tight ratio clusters in the smooth wheel speed that GPS shows as the continuum they
// belong to), or when it finds more gears than the wheel speed does (whole km/h can blur a low gear).
[[nodiscard]] FitResult fit_gear_model_two_speeds(std::span<const TwoSpeedLog> logs,
                                                  const FitOptions& options);

}  // namespace gearpulse
