#pragma once
// Pieces shared by the estimator's translation units (not part of the public API).
#include <string>
#include <vector>

#include "core/gear_model.hpp"
#include "core/mixture_likelihood.hpp"

namespace gearpulse::detail {

// Paper mode: M = ratios.size() + 1, ratios top gear down (Table 2's c_i).
[[nodiscard]] GearModel fit_paper(const MixtureData& data, const std::vector<double>& ratios);

// Auto mode: gears = 0 chooses the count from the data, else exactly that many.
[[nodiscard]] GearModel fit_auto(const MixtureData& data, int gears);

// Fills a GearModel from fitted parameters: log-likelihood, standard errors of theta from the inverse of
// the observed information (layout chooses which nuisance parameters are estimated alongside).
[[nodiscard]] GearModel finish_model(const MixtureData& data, const MixtureParams& p,
                                     const std::string& method, const GradientLayout& layout);

}  // namespace gearpulse::detail
