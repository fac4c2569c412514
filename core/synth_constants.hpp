#pragma once
// Constants the files of the mode filter (SpeedSynthesizer, core/speed_synth.hpp) share: speed_synth.cpp
// (its state, time and tracker gaps), synth_step.cpp (one step), synth_rates.cpp (the mode changes) and
// synth_evidence.cpp (the scores), synth_ladder.cpp (the ladder) and synth_ladder_insert.cpp (the gears that
// join it).
#include <algorithm>
#include <array>
#include <cstddef>
#include <span>

#include "core/gear_model.hpp"

namespace gearpulse::synth {

constexpr double kMovingOffSpeed = 2.0;  // m/s: below this a declutched car may be moving off
constexpr double kDeadZone = 2.0;        // sigmas of a gear's reading that are ordinary jitter
// A step shorter than this share of accel_time (0.3 s) is the tracker's hop, not a GPS or OBD row: one
// reading to the next is shorter than a shift.
constexpr double kShortStep = 0.1;
// s: the tracker refuses hops in gaps of a few tenths of a second (docs/tracker.md: 4-11 % of the in-band
// hops at 0-10 dB), and a log's row may fall on such a hop: a reading lost for this long or less says
// nothing of the mode. Lost for longer, the engine's line is gone.
constexpr double kTrackerGap = 1.0;

// Log-cost of a departure of z2 squared sigmas as an event: what lies beyond the dead zone, paid once.
constexpr double jump_cost(double z2) noexcept {
  return 0.5 * std::max(z2 - kDeadZone * kDeadZone, 0.0);
}

constexpr double kMinGearShare = 0.02;  // no gear is ever ruled out by its training weight

// The model's thetas in `buf` (empty without a model).
inline std::span<const double> thetas_of(const GearModel* model,
                                         std::array<double, GearModel::kMaxGears>& buf) noexcept {
  std::size_t n = 0;
  if (model != nullptr)
    for (; n < model->gears.size() && n < buf.size(); ++n)
      buf[n] = model->gears[n].theta;
  return {buf.data(), n};
}

}  // namespace gearpulse::synth
