#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "core/speed_synth.hpp"
#include "core/synth_habits.hpp"
#include "tests/town_drive.hpp"

using gearpulse::GearModel;
using gearpulse::kMissing;
using gearpulse::SpeedSynthesizer;
using gearpulse::SynthHabits;
using gearpulse::SynthOutput;
using gearpulse::SynthTuning;
using gearpulse::test::kHatch;
using gearpulse::test::kIdle;
using gearpulse::test::model_of;

namespace {

// A model of kHatch whose fit saw a steady warm idle (its spread below the 3 % floor) and this driver's revs
// per gear: first gear from a creep upward, every gear above it at `held` x the idle (+-15 %), each gear
// seen on `samples` samples.
std::shared_ptr<const GearModel> model_with_revs(double held, double samples = 2000) {
  auto m = std::make_shared<GearModel>(*model_of(kHatch));
  m->extra["idle"] = {{"freq", kIdle}, {"sd", 0.2}, {"samples", 500}};
  nlohmann::json revs = nlohmann::json::array();
  revs.push_back({{"mean_log", std::log(1.5 * kIdle)}, {"sd_log", 0.3}, {"samples", samples}});
  for (std::size_t i = 1; i < kHatch.size(); ++i)
    revs.push_back({{"mean_log", std::log(held * kIdle)}, {"sd_log", 0.15}, {"samples", samples}});
  m->extra["revs"] = std::move(revs);
  return m;
}

struct Row {
  double t, speed, freq;
};

// At the daemon's cadence (the frequency every 0.1 s, a 1 Hz fix until `lost`): 20 s at rest at a steady
// idle, away through 1st, 2nd and 3rd to 10 m/s, GPS lost; then the clutch out, braking at 1.2 m/s^2 with
// the engine held at `creep_revs` x the idle down to first gear's speed at those revs, and creeping in first
// gear at them for 30 s (a queue).
std::vector<Row> brake_into_a_creep(double creep_revs, double& lost) {
  std::vector<Row> rows;
  const double creep = kHatch[0] * creep_revs * kIdle;
  double t = 0.0, v = 0.0;
  const auto add = [&](double seconds, int gear, double accel, double declutched_freq) {
    for (double end = t + seconds; t < end - 1e-9; t += 0.1) {
      v = std::max(v + accel * 0.1, 0.0);
      rows.push_back({t, v, gear > 0 ? v / kHatch[static_cast<std::size_t>(gear - 1)] : declutched_freq});
    }
  };
  add(20.0, 0, 0.0, kIdle);
  add(2.0, 1, 1.5, 0.0);
  add(4.0, 2, 1.2, 0.0);
  add(6.0, 3, 0.6, 0.0);
  add(10.0, 3, 0.0, 0.0);
  lost = t;
  add((v - creep) / 1.2, 0, -1.2, creep_revs * kIdle);
  v = creep;
  add(30.0, 1, 0.0, 0.0);
  return rows;
}

// Steps `synth` over the rows at the daemon's cadence: a fix measured once a second, held between.
std::vector<SynthOutput> replay(SpeedSynthesizer& synth, const std::vector<Row>& rows, double lost) {
  std::vector<SynthOutput> out;
  double fix = kMissing;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const bool fresh = rows[k].t < lost && k % 10 == 0;
    if (fresh) fix = rows[k].speed;
    out.push_back(synth.step(rows[k].t, rows[k].t < lost ? fix : kMissing, rows[k].freq, fresh));
  }
  return out;
}

// Of the last 20 s, the seconds whose output is within 1 m/s of the creep.
int seconds_creeping(const std::vector<Row>& rows, const std::vector<SynthOutput>& out) {
  int creeping = 0;
  for (std::size_t k = rows.size() - 200; k < rows.size(); k += 10) {
    const bool close = std::abs(out[k].speed - rows[k].speed) < 1.0;
    if (!close)
      UNSCOPED_INFO("t = " << rows[k].t << ", truth " << rows[k].speed << " m/s, synthesized " << out[k].speed
                           << " in gear " << out[k].gear);
    creeping += close ? 1 : 0;
  }
  return creeping;
}

}  // namespace

TEST_CASE(
    "synth lugging: a creep above a steady idle is first gear where the driver holds higher gears higher") {
  // The car brakes out of gear in an outage, the engine held at 1.2 x its idle, and creeps on in first gear
  // at those revs. GPS showed the idle steady, so its spread is at its floor (3 % of it): 1.2 x the idle
  // lies 6 spreads above it. This driver holds every gear above first at twice the idle (the fit's revs per
  // gear): 1.2 x the idle lugs them, and the creep is first gear (2.0 m/s), not fifth (9.2 m/s), whose line
  // the braking car passed at those revs.
  double lost = 0.0;
  const auto rows = brake_into_a_creep(1.2, lost);
  SpeedSynthesizer synth(model_with_revs(2.0));
  CHECK(seconds_creeping(rows, replay(synth, rows, lost)) == 20);
}

TEST_CASE("synth lugging: a young model's few samples of its gears' revs move the band little") {
  // The first model of a drive has seen each gear on a few samples, all at twice the idle: they do not yet
  // show that this driver never holds a gear at 1.35 x the idle, and the band stays near the idle's floor.
  // Thousands of samples do show it.
  const SynthTuning tuning;
  const auto lugged_at = [&](double samples) {
    const auto model = model_with_revs(2.0, samples);
    SynthHabits habits;
    habits.load_engine(gearpulse::read_model_extras(model.get()), tuning);
    SynthHabits::GearNumbers numbers{};
    for (int j = 1; j <= static_cast<int>(kHatch.size()); ++j)
      numbers[static_cast<std::size_t>(j)] = j;
    habits.load_gear_revs(gearpulse::read_model_extras(model.get()), numbers,
                          static_cast<int>(kHatch.size()));
    return habits.lugged(1.35 * kIdle, static_cast<int>(kHatch.size()), tuning);
  };
  CHECK(lugged_at(5) < 0.35);
  CHECK(lugged_at(2000) > 0.9);
}
