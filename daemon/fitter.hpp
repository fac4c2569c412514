#pragma once
// The model fit the retrainer runs: the same estimator as `gearpulse fit`, and the rule that keeps the
// gears a model has learned when a refit on the pairs at hand does not find them.
#include <cstddef>
#include <span>

#include "core/gear_model.hpp"
#include "core/sample.hpp"
#include "daemon/retrainer.hpp"

namespace gearpulse::daemon {

// The auto fit (no priors, the gear count from the data), which may find one gear alone: a model still
// learning that has seen the car in one gear so far (FitOptions::single_gear).
[[nodiscard]] Retrainer::Fitter make_estimator_fitter();

// Key in a model's `extra` object: the thetas of the gears keep_seen_gears carried over from the model
// before, ascending.
inline constexpr const char* kKeptGears = "kept_gears";

// `fitted`, with every gear of `current` it lacks that the pairs do not contradict. A gear is the same as a
// fitted one within a gearbox step (a factor of 1.06: the refit moved it, its value wins). One the fit has
// no gear near is contradicted when the steady pairs (steady_log_ratios) within three gear windows
// (kGearWindow) of its line number at least `judge_pairs` and show no line there: the window on it holds
// fewer than the two beside it (twice as wide), a density at most twice theirs, as driving through a
// continuum gives (a CVT, clutch slip: about equal densities), where a gear's line holds nearly all of them
// (GPS and tracker noise spread it by 1-2 %, within one window). Fewer pairs near it are no evidence: the
// gear was not driven in them. A kept gear keeps its theta and standard error, its weight scaled with the
// fit's gear weights, its per-gear revs; none is kept that would make more than GearModel::kMaxGears.
[[nodiscard]] GearModel keep_seen_gears(const GearModel& current, GearModel fitted,
                                        std::span<const Sample> pairs, std::size_t judge_pairs);

// Whether a model of one gear has lost the ground it was accepted on (FitOptions::single_gear) when a
// refit finds no ladder: the steady pairs off its line (beyond a gearbox step of it) number at least 30,
// what a fit needs, and spread as a continuum does, their densest gear window holding under a quarter of
// them. A CVT holds one ratio at cruise, as sharp a line as a gear's, and drives through the ratios below
// it (on simulated drives the densest window holds 12-20 % of those pairs); a gearbox's other gears gather
// theirs in a window each (32 % and more). A model of any other size is never withdrawn.
[[nodiscard]] bool one_gear_withdrawn(const GearModel& current, std::span<const Sample> pairs);

}  // namespace gearpulse::daemon
