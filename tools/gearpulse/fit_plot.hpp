#pragma once
// `gearpulse fit --plot`: an SVG of the histogram of speed / frequency (the paper's Fig. 1, 200 bins) with
// vertical lines at the fitted thetas and the fitted mixture density (eq. (6)) laid over it, so a fit can be
// checked by eye. Hand-written SVG, no dependencies.
#include <span>
#include <string>

#include "core/gear_model.hpp"
#include "core/sample.hpp"

namespace gearpulse::cli {

[[nodiscard]] std::string ratio_histogram_svg(std::span<const Sample> samples, const GearModel& model);

}  // namespace gearpulse::cli
