#pragma once
// Gear-scale estimation from unlabelled (speed, frequency) samples.
// "paper" mode: the ML estimator of eqs. (6)-(9) with the initialisation (11)-(16) and Table 2 constants.
// "auto" mode (default): no priors; gear count, weights and the clutch-out density come from the data.
#include <span>
#include <string>
#include <vector>

#include "core/gear_model.hpp"
#include "core/sample.hpp"

namespace gearpulse {

struct FitOptions {
  int gears = 0;               // 0 = choose from the data; N = exactly N gears
  std::vector<double> ratios;  // paper's c_i, top gear down as Table 2 (c1 ~ theta_M/theta_{M-1});
                               // non-empty selects the paper's method with M = ratios.size() + 1
};

struct FitResult {
  GearModel model;  // gears empty when no discrete ladder exists; model.reason says why
};

// Samples lacking speed or frequency are ignored. Throws std::invalid_argument for unusable options.
[[nodiscard]] FitResult fit_gear_model(std::span<const Sample> samples, const FitOptions& options);

}  // namespace gearpulse
