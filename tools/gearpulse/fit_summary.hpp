#pragma once
// What `gearpulse fit` tells its user on stderr after a fit with gears: how many gears, each gear's scale in
// a car's own terms, how much driving each rests on and at what speeds, and what to log when that is thin.
#include <span>
#include <string>

#include "core/estimator.hpp"
#include "core/gear_model.hpp"
#include "core/sample_io.hpp"

namespace gearpulse::cli {

// A gear's theta whose standard error exceeds this (relative) is named as rough: a third of the window
// that never holds two gears (kGearWindow), so the gear of a reading is no longer told at three standard
// errors; the speed synthesized in that gear is off by at least as much.
inline constexpr double kRoughGear = kGearWindow / 3.0;

// The lines printed (each ending in '\n'); empty for a model without gears. `samples` are those the fit
// read (what --plot shows), `rpm_logs` whether every log's frequency is rpm / 60 (any format but the
// generic t,speed,freq, whose freq may be a harmonic of the ripple), to say each gear in km/h per 1000 rpm.
[[nodiscard]] std::string fit_summary(const GearModel& model, std::span<const Sample> samples, bool rpm_logs);

}  // namespace gearpulse::cli
