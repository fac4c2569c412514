// The synthesis on the hatch's ladder: GPS, gears kept and followed in outages, coasting, the belief's speed.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "core/estimator.hpp"
#include "core/speed_synth.hpp"
#include "tests/core/synth_drives.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::GearModel;
using gearpulse::kMissing;
using gearpulse::SpeedSource;
using gearpulse::SpeedSynthesizer;
using gearpulse::SynthOutput;

using gearpulse::test::kHatch;
using gearpulse::test::kIdle;
using gearpulse::test::kKmh;
using gearpulse::test::model_of;
using gearpulse::test::replay;
using gearpulse::test::script;

TEST_CASE("synth: without a model GPS passes through and an outage holds its last speed, then stops") {
  SpeedSynthesizer synth;
  // No GPS yet: nothing is known.
  SynthOutput o = synth.step(0.0, kMissing, 40.0);
  CHECK(o.source == SpeedSource::kNone);
  CHECK(o.speed == 0.0);
  CHECK(gearpulse::source_name(o.source) == "none");
  o = synth.step(1.0, 12.5, 40.0);
  CHECK(o.source == SpeedSource::kGps);
  CHECK(o.speed == 12.5);
  CHECK(o.gear == 0);
  // The frequency says nothing of the speed without a ladder: a tunnel is driven at the speed going in...
  const double hold = gearpulse::SynthTuning{}.hold_time;
  o = synth.step(2.0, kMissing, 80.0);
  CHECK(o.source == SpeedSource::kCoast);
  CHECK(o.speed == 12.5);
  CHECK(synth.step(1.0 + hold, kMissing, 20.0).speed == 12.5);
  // ... and a long outage most likely ends parked: down to rest at the coasting deceleration.
  o = synth.step(1.0 + hold + 5.0, kMissing, 20.0);
  CHECK(o.speed == Approx(12.5 + 5.0 * gearpulse::SynthTuning{}.coast_accel));
  o = synth.step(1.0 + hold + 60.0, kMissing, 20.0);
  CHECK(o.speed == 0.0);
  CHECK(o.source == SpeedSource::kCoast);

  // A model without gears (an automatic, a CVT) alike.
  SpeedSynthesizer empty(std::make_shared<const GearModel>());
  CHECK(empty.step(0.0, 3.0, 20.0).source == SpeedSource::kGps);
  o = empty.step(1.0, kMissing, 20.0);
  CHECK(o.source == SpeedSource::kCoast);
  CHECK(o.speed == 3.0);
}

TEST_CASE("synth: tracks the gear while GPS is present") {
  SpeedSynthesizer synth(model_of(kHatch));
  const auto rows = script(0.0, {{0, 0.0, 10}, {1, 1.5, 4}, {2, 1.0, 6}, {3, 0.5, 10}}, kHatch);
  const auto out = replay(synth, rows, 1e9);
  CHECK(out[5].gear == 0);  // standing
  CHECK(out[12].gear == 1);
  CHECK(out.back().gear == 3);
  CHECK(out.back().source == SpeedSource::kGps);
  CHECK(synth.idle_freq() == Approx(kIdle));
}

TEST_CASE("synth: keeps the gear and follows the frequency through an outage") {
  SpeedSynthesizer synth(model_of(kHatch));
  const auto rows = script(
      0.0, {{0, 0.0, 10}, {1, 1.5, 4}, {2, 1.0, 6}, {3, 0.4, 10}, {3, -0.3, 20}, {3, 0.2, 20}}, kHatch);
  const auto out = replay(synth, rows, 35.0);
  for (std::size_t i = 36; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].source == SpeedSource::kEngine);
    CHECK(out[i].gear == 3);
    CHECK(out[i].speed == Approx(rows[i].speed).margin(0.5 * kKmh));
  }
}

// The tracker refuses a hop now and then (a gap of a few tenths of a second), and a 1 Hz row falls on one:
// a reading lost that briefly is no sign that the clutch went out.
TEST_CASE("synth: a frequency reading lost now and then keeps the gear through an outage") {
  SpeedSynthesizer synth(model_of(kHatch));
  auto rows = script(0.0, {{0, 0.0, 10}, {1, 1.5, 4}, {2, 1.0, 6}, {3, 0.4, 10}, {3, -0.3, 20}, {3, 0.2, 20}},
                     kHatch);
  for (std::size_t i = 37; i < rows.size(); i += 4)
    rows[i].freq = kMissing;
  const auto out = replay(synth, rows, 35.0);
  for (std::size_t i = 36; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].gear == 3);
    CHECK(out[i].speed == Approx(rows[i].speed).margin(0.5 * kKmh));
  }
}

// Rows at 1 Hz with one reading in ten lost, a car fitted on its own drive: in a jam, second gear through an
// outage, the revs sagging to 27 Hz, three rows lost within 10 s. Stepped as rows of their own, each lost
// row moved the modes with nothing to tell them apart and merged their histories; when the car pulled away
// in second, 20 s later, the filter took first gear and the clutch, and the outage ended 54 % short. Taken
// with the next reading as one step, every history is scored against that reading from where it stood.
TEST_CASE("synth: a lost row in an outage is stepped over with the next reading") {
  const auto car = gearpulse::sim::vehicle_preset("compact-4");
  const auto fitted = gearpulse::sim::simulate_drive(car, {.duration = 2400.0, .seed = 102});
  const auto model = std::make_shared<const GearModel>(
      gearpulse::fit_gear_model(gearpulse::sim::to_samples(gearpulse::sim::observe(fitted, {})), {}).model);
  const auto drive = gearpulse::sim::simulate_drive(car, {.style = gearpulse::sim::DrivingStyle::kTrafficJam,
                                                          .duration = 1200.0,
                                                          .dt = 0.1,
                                                          .seed = 2,
                                                          .skip_downshift = 0.3});
  // The outage's distance error (synthesized / driven - 1) with the rows as the tuning has them.
  const auto outage_error = [&](const gearpulse::SynthTuning& tuning) {
    SpeedSynthesizer synth(model, tuning);
    std::mt19937_64 rng(2);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    double driven = 0.0, synthesized = 0.0;
    for (int t = 0; t <= 180; ++t) {
      const auto truth = gearpulse::sim::truth_at(drive, t);
      const double freq = unit(rng) < 0.1 ? kMissing : truth.freq;
      const SynthOutput o = synth.step(t, t < 120 ? truth.speed : kMissing, freq);
      if (t >= 120) driven += truth.speed, synthesized += o.speed;
    }
    return synthesized / driven - 1.0;
  };
  // The row-by-row failure took the pull-away in a creep's ratio seen under GPS as a gear; a gear seen only
  // at lugged revs (creep_gears) no longer takes it (-0.12 % row by row), so it is switched off here to keep
  // the gaps' own part in view.
  gearpulse::SynthTuning row_by_row;
  row_by_row.gap_one_step = 0.0;
  row_by_row.creep_gears = 0.0;
  const double stepped_over = outage_error({}), each_row = outage_error(row_by_row);
  INFO("outage distance error " << 100.0 * stepped_over << " % stepped over, " << 100.0 * each_row
                                << " % row by row");
  CHECK(std::abs(stepped_over) < 0.02);
  CHECK(each_row < -0.3);
}

TEST_CASE("synth: the belief's spread is none under GPS, small in a gear, larger coasting declutched") {
  SpeedSynthesizer synth(model_of(kHatch));
  // GPS lost at 30 s cruising in 3rd; braking in gear, then declutched at idle and braking to a stop.
  const auto rows = script(
      0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.3, 15}, {3, -1.0, 5}, {0, -1.5, 10}, {0, 0.0, 20}},
      kHatch);
  const auto out = replay(synth, rows, 30.0);
  for (std::size_t i = 0; i < 30; ++i)
    CHECK(out[i].speed_sd == 0.0);
  const std::size_t declutch = 8 + 3 + 8 + 15 + 5;
  double in_gear = 0.0, coasting = 0.0;
  for (std::size_t i = 32; i < declutch; ++i)
    in_gear = std::max(in_gear, out[i].speed_sd);
  for (std::size_t i = declutch + 1; i < declutch + 4; ++i)
    coasting = std::max(coasting, out[i].speed_sd);
  INFO("spread in gear " << in_gear << " m/s, coasting " << coasting << " m/s");
  CHECK(in_gear > 0.0);
  CHECK(in_gear < 0.5);
  CHECK(coasting > 2.0 * in_gear);
}

TEST_CASE("synth: follows up- and downshifts inside an outage") {
  SpeedSynthesizer synth(model_of(kHatch));
  // Outage from 20 s: 2nd -> 3rd -> 4th while accelerating, then back down to 3rd while slowing.
  const auto rows = script(0.0,
                           {{0, 0.0, 8},
                            {1, 1.8, 3},
                            {2, 1.2, 12},
                            {3, 0.8, 10},
                            {4, 0.4, 15},
                            {4, -0.8, 8},
                            {3, -0.5, 10},
                            {3, 0.0, 10}},
                           kHatch);
  const auto out = replay(synth, rows, 20.0);
  int right = 0, total = 0;
  double worst = 0.0;
  for (std::size_t i = 20; i < rows.size(); ++i) {
    ++total;
    right += out[i].gear == rows[i].gear;
    worst = std::max(worst, std::abs(out[i].speed - rows[i].speed));
  }
  CHECK(right >= total - 3);  // a shift may be recognised one sample late
  CHECK(worst < 12.0 * kKmh);
  CHECK(out.back().gear == 3);
  CHECK(out.back().speed == Approx(rows.back().speed).margin(1.0 * kKmh));
}

TEST_CASE("synth: coasts through clutch-out and comes to zero at a stop") {
  SpeedSynthesizer synth(model_of(kHatch));
  // Drive, GPS lost at 30 s in 3rd, brake in gear, declutch at idle, stand for 20 s at the light.
  const auto rows = script(
      0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.3, 15}, {3, -1.0, 5}, {0, -1.5, 10}, {0, 0.0, 20}},
      kHatch);
  const auto out = replay(synth, rows, 30.0);
  const std::size_t declutch = 8 + 3 + 8 + 15 + 5;
  bool coasted = false;
  for (std::size_t i = declutch; i < declutch + 6; ++i)
    coasted = coasted || out[i].source == SpeedSource::kCoast;
  CHECK(coasted);
  REQUIRE(rows[declutch + 10].speed == 0.0);
  // Declutched at idle the estimate only ever falls (no gear hypothesis lifts it again), and it reaches
  // zero while the car still waits at the light: without GPS the firmness of the braking is unknown.
  for (std::size_t i = declutch + 1; i < rows.size(); ++i)
    CHECK(out[i].speed <= out[i - 1].speed + 1e-9);
  for (std::size_t i = declutch + 20; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].speed == 0.0);
    CHECK(out[i].gear == 0);
    CHECK(out[i].source == SpeedSource::kCoast);
  }
  // Never faster than the car was, never negative.
  for (std::size_t i = 30; i < rows.size(); ++i)
    CHECK(out[i].speed >= 0.0);
}

TEST_CASE("synth: a frequency no gear explains is coasted through") {
  SpeedSynthesizer synth(model_of(kHatch));
  auto rows = script(0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.0, 20}}, kHatch);
  const double v = rows.back().speed;
  // Clutch pressed with a blip of throttle: revs far above any gear's, then the tone lost entirely (for
  // longer than the tracker's gaps of a few tenths of a second, which say nothing of the mode).
  rows.push_back({rows.back().t + 1, v, 95.0, 0});
  rows.push_back({rows.back().t + 1, v, kMissing, 0});
  rows.push_back({rows.back().t + 1, v, kMissing, 0});
  rows.push_back({rows.back().t + 1, v, v / kHatch[2], 3});
  const auto out = replay(synth, rows, 30.0);
  const std::size_t n = rows.size();
  CHECK(out[n - 4].source == SpeedSource::kCoast);
  CHECK(out[n - 2].source == SpeedSource::kCoast);
  for (std::size_t i = n - 4; i < n - 1; ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].speed < v);
    CHECK(out[i].speed > v - 1.0);  // gentle: a shift does not stop the car
  }
  CHECK(out[n - 1].gear == 3);
  CHECK(out[n - 1].speed == Approx(v).margin(1.0 * kKmh));
}

TEST_CASE("synth: a split belief's contenders pull the speed as the square of their belief") {
  using gearpulse::contended_speed;
  // Between two modes, the speed of least expected |error|^1.5, found here by a search over a fine grid.
  const auto least = [](double p1, double v1, double p2, double v2) {
    double best = v2, best_cost = std::numeric_limits<double>::infinity();
    for (double a = v2; a <= v1; a += 1e-4) {
      const double cost = p1 * std::pow(v1 - a, 1.5) + p2 * std::pow(a - v2, 1.5);
      if (cost < best_cost) best = a, best_cost = cost;
    }
    return best;
  };
  for (const double p1 : {0.5, 0.6, 0.8, 0.95}) {
    const std::vector<double> prob = {p1, 1.0 - p1}, speed = {11.0, 8.5};  // third and second at 40, 31 km/h
    INFO("leader's share " << p1);
    CHECK(contended_speed(prob, speed) == Approx(least(p1, 11.0, 1.0 - p1, 8.5)).margin(1e-3));
  }
  // A clear leader keeps its speed; an even split lies halfway; one mode is its own speed; no belief, 0.
  CHECK(contended_speed(std::vector<double>{0.95, 0.05}, std::vector<double>{11.0, 8.5}) > 10.99);
  CHECK(contended_speed(std::vector<double>{0.5, 0.5}, std::vector<double>{11.0, 8.5}) == Approx(9.75));
  CHECK(contended_speed(std::vector<double>{0.0, 1.0, 0.0}, std::vector<double>{3.0, 7.0, 9.0}) == 7.0);
  CHECK(contended_speed(std::vector<double>{0.0, 0.0}, std::vector<double>{3.0, 7.0}) == 0.0);
}

TEST_CASE("synth: the output's mode is the belief's quantile by speed") {
  using gearpulse::belief_quantile_mode;
  // The q-quantile of a belief is the speed of least expected pinball loss (a slower output costs q per
  // m/s, a faster one 1 - q): found here by trying every mode's speed, over beliefs drawn at random.
  const auto least_pinball = [](const std::vector<double>& prob, const std::vector<double>& speed, double q) {
    double best = speed[0], best_cost = std::numeric_limits<double>::infinity();
    for (const double a : speed) {
      double cost = 0.0;
      for (std::size_t j = 0; j < prob.size(); ++j)
        cost += prob[j] * (speed[j] > a ? q * (speed[j] - a) : (1.0 - q) * (a - speed[j]));
      if (cost < best_cost - 1e-12) best = a, best_cost = cost;
    }
    return best;
  };
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int round = 0; round < 200; ++round) {
    const std::size_t n = 2 + round % 6;
    std::vector<double> prob(n), speed(n);
    double total = 0.0;
    for (std::size_t j = 0; j < n; ++j) {
      prob[j] = std::pow(unit(rng), 3.0);
      speed[j] = 30.0 * unit(rng);
      total += prob[j];
    }
    for (double& p : prob)
      p /= total;
    for (const double q : {0.5, 0.6, 0.65}) {
      INFO("round " << round << ", q " << q);
      const int mode = belief_quantile_mode(prob, speed, q);
      REQUIRE(mode >= 0);
      CHECK(speed[static_cast<std::size_t>(mode)] == least_pinball(prob, speed, q));
    }
  }
  // Third gear leads second 0.55 to 0.45: the median keeps third, a quantile of 0.6 takes fourth when it
  // holds the rest; a leader holding at least q is its own quantile whatever the speeds.
  const std::vector<double> speed = {8.5, 11.0, 14.0};  // second, third, fourth at 31, 40, 50 km/h
  CHECK(belief_quantile_mode(std::vector<double>{0.45, 0.55, 0.0}, speed, 0.5) == 1);
  CHECK(belief_quantile_mode(std::vector<double>{0.0, 0.55, 0.45}, speed, 0.5) == 1);
  CHECK(belief_quantile_mode(std::vector<double>{0.0, 0.55, 0.45}, speed, 0.6) == 2);
  CHECK(belief_quantile_mode(std::vector<double>{0.35, 0.65, 0.0}, speed, 0.6) == 1);
  // Modes of one speed (negligible ones carry the leader's history) count as one, named by its leader.
  CHECK(belief_quantile_mode(std::vector<double>{0.3, 0.31, 0.33, 0.06},
                             std::vector<double>{8.5, 11.0, 11.0, 14.0}, 0.6) == 2);
  CHECK(belief_quantile_mode(std::vector<double>{}, std::vector<double>{}, 0.6) == -1);
}
