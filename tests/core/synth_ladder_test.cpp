// The synthesis's ladder swapped mid-drive (without allocating), and a ladder lacking a gear GPS showed.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstddef>
#include <limits>
#include <memory>
#include <vector>

#include "core/speed_synth.hpp"
#include "tests/alloc_counter.hpp"
#include "tests/core/synth_drives.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::GearModel;
using gearpulse::kMissing;
using gearpulse::SpeedSource;
using gearpulse::SpeedSynthesizer;
using gearpulse::SynthOutput;

using gearpulse::test::g_allocations;
using gearpulse::test::kHatch;
using gearpulse::test::model_of;
using gearpulse::test::replay;
using gearpulse::test::Row;
using gearpulse::test::script;

TEST_CASE("synth: a model swap mid-outage keeps the output continuous") {
  SpeedSynthesizer synth(model_of(kHatch));
  const auto rows = script(0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.0, 30}}, kHatch);
  std::vector<SynthOutput> out;
  for (const Row& r : rows) {
    if (r.t == 40.0) {
      CHECK(synth.set_model(model_of(kHatch, 1.004)));  // retrained: thetas moved by 0.4 %
    }
    if (r.t == 45.0) {
      CHECK(synth.set_model(model_of({0.2, 0.35, 0.47, 0.58})));  // a different ladder
    }
    out.push_back(synth.step(r.t, r.t < 30.0 ? r.speed : kMissing, r.freq));
  }
  CHECK(out[40].gear == 3);
  CHECK(std::abs(out[40].speed - out[39].speed) < 0.01 * out[39].speed);
  CHECK(std::abs(out[45].speed - out[44].speed) < 0.05 * out[44].speed);
  CHECK(out[45].source == SpeedSource::kEngine);

  // Dropping the model: an outage then holds the last GPS speed (from 29 s, 71 s ago: coming to rest),
  // GPS still passes.
  synth.set_model(nullptr);
  const SynthOutput dropped = synth.step(100.0, kMissing, 30.0);
  CHECK(dropped.source == SpeedSource::kCoast);
  CHECK(dropped.speed < out[29].speed);
  CHECK(synth.step(101.0, 5.0, 30.0).source == SpeedSource::kGps);
  // More gears than the fixed capacity: refused, the old model stays.
  std::vector<double> many;
  for (int i = 0; i < SpeedSynthesizer::kMaxGears + 1; ++i)
    many.push_back(0.05 * (i + 1));
  CHECK_FALSE(synth.set_model(model_of(many)));
  CHECK(synth.model() == nullptr);
}

TEST_CASE("synth: step never allocates") {
  auto vehicle = gearpulse::sim::vehicle_preset("hatch-5");
  const auto drive = gearpulse::sim::simulate_drive(vehicle, {.duration = 600.0, .seed = 3});
  const auto samples = gearpulse::sim::to_samples(gearpulse::sim::observe(drive, {.seed = 4}));
  SpeedSynthesizer synth(model_of(vehicle.theta));
  // The replacement carries what a fit records beyond the ratios (idle, revs per gear): loading it
  // allocates nothing either.
  auto replacement = std::make_shared<GearModel>(*model_of(vehicle.theta, 1.01));
  replacement->extra["idle"] = {{"freq", vehicle.idle_freq}, {"sd", 0.3}, {"samples", 100}};
  replacement->extra["revs"] = nlohmann::json::array();
  for (std::size_t g = 0; g < vehicle.theta.size(); ++g)
    replacement->extra["revs"].push_back({{"mean_log", 3.3}, {"sd_log", 0.25}, {"samples", 100}});
  const long before = g_allocations.load();
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const auto& s = samples[i];
    const bool outage = (i / 60) % 2 == 1;
    (void)synth.step(s.t, outage ? kMissing : s.speed, s.freq);
    if (i == samples.size() / 2) synth.set_model(replacement);
  }
  CHECK(g_allocations.load() == before);
  static_assert(noexcept(synth.step(0.0, 0.0, 0.0)));
  // Nor does a ladder that gains a gear measured under GPS (the model lacks the car's third gear), or a
  // model swapped in beside it.
  std::vector<double> lacking = vehicle.theta;
  lacking.erase(lacking.begin() + 2);
  SpeedSynthesizer young(model_of(lacking));
  auto young_replacement = std::make_shared<GearModel>(*model_of(lacking, 1.01));
  young_replacement->extra = replacement->extra;
  young_replacement->extra["revs"].erase(2);
  int in_seen_gear = 0;
  const long young_before = g_allocations.load();
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const auto& s = samples[i];
    const bool outage = (i / 60) % 2 == 1;
    const SynthOutput out = young.step(s.t, outage ? kMissing : s.speed, s.freq);
    in_seen_gear += out.source == SpeedSource::kEngine && out.gear == 0 ? 1 : 0;
    if (i == samples.size() / 2) young.set_model(young_replacement);
  }
  CHECK(g_allocations.load() == young_before);
  CHECK(in_seen_gear > 0);
}

TEST_CASE("synth: a step it cannot take after a swap to a shorter ladder names no gear the ladder lacks") {
  SpeedSynthesizer synth(model_of(kHatch));
  for (int k = 0; k < 30; ++k)
    synth.step(k, 20.0, 20.0 / kHatch[4]);  // fifth gear
  REQUIRE(synth.last().gear == 5);
  REQUIRE(synth.set_model(model_of({0.125, 0.225, 0.347})));
  const SynthOutput o = synth.step(std::numeric_limits<double>::quiet_NaN(), 20.0, 50.0);
  CHECK(o.gear <= 3);
}

TEST_CASE("synth: an outage in a gear the model lacks follows the ratio GPS showed in it") {
  // The model lacks fourth gear (a young model, or a fit that missed it). The car moves off, climbs to
  // fourth and cruises in it with GPS, then GPS is lost while it stays in fourth.
  const std::vector<double> lacking = {kHatch[0], kHatch[1], kHatch[2], kHatch[4]};
  const double outage_from = 80.0;
  const auto rows = script(0.0,
                           {{0, 0.0, 20},
                            {1, 1.5, 3},
                            {0, -0.2, 1},
                            {2, 1.2, 4},
                            {0, -0.2, 1},
                            {3, 1.0, 5},
                            {0, -0.2, 1},
                            {4, 0.5, 4},
                            {4, 0.0, 41},
                            {4, 0.3, 15},
                            {4, -0.3, 15}},
                           kHatch);
  const auto distance = [&](const gearpulse::SynthTuning& tuning) {
    SpeedSynthesizer synth(model_of(lacking), tuning);
    const auto out = replay(synth, rows, outage_from);
    double synthesized = 0.0, driven = 0.0;
    for (std::size_t i = 1; i < rows.size(); ++i) {
      if (rows[i].t <= outage_from) continue;
      INFO("t = " << rows[i].t << ": truth " << rows[i].speed * 3.6 << " km/h, synthesized "
                  << out[i].speed * 3.6 << " in gear " << out[i].gear);
      const double dt = rows[i].t - rows[i - 1].t;
      synthesized += out[i].speed * dt;
      driven += rows[i].speed * dt;
    }
    // The outage runs on a gear the model does not number.
    CHECK(out.back().source == SpeedSource::kEngine);
    CHECK(out.back().gear == 0);
    return synthesized / driven - 1.0;
  };
  CHECK(std::abs(distance({})) < 0.01);
  // Without the gear measured under GPS, the outage takes one of the model's.
  gearpulse::SynthTuning without;
  without.seen_gear_fixes = std::numeric_limits<double>::infinity();
  SpeedSynthesizer blind(model_of(lacking), without);
  const auto out = replay(blind, rows, outage_from);
  CHECK(std::abs(out.back().speed / rows.back().speed - 1.0) > 0.1);
}

TEST_CASE("synth: a gear measured under GPS gives way to the model's own once a model has it") {
  const std::vector<double> lacking = {kHatch[0], kHatch[1], kHatch[2], kHatch[4]};
  SpeedSynthesizer synth(model_of(lacking));
  replay(synth, script(16.0, {{4, 0.0, 30}}, kHatch), 1e9);
  // The belief is in a gear, and in none of the model's.
  double in_model = 0.0;
  for (int g = 1; g <= 4; ++g)
    in_model += synth.mode_probability(g);
  CHECK(synth.mode_probability(0) < 0.1);
  CHECK(in_model < 0.1);
  CHECK(synth.last().gear == 0);
  REQUIRE(synth.set_model(model_of(kHatch)));
  for (double t = 30.0; t < 35.0; t += 1.0)
    synth.step(t, 16.0, 16.0 / kHatch[3]);
  CHECK(synth.last().gear == 4);
  CHECK(synth.mode_probability(4) > 0.9);
}
