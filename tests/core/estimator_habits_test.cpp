// What a fit records of the driver beside the ladder (the model's extra): the idle standing and rolling,
// the braking declutched at idle, the revs each gear is driven at.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstddef>
#include <vector>

#include "core/estimator.hpp"
#include "tests/core/estimator_drives.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;
using gearpulse::test::read_etios;

TEST_CASE("estimator: a fit records the engine's idle from the samples standing still") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  const auto samples =
      sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kUrban, 1200.0, 1, 3));
  const FitResult r = fit_gear_model(samples, {});
  REQUIRE(r.model.extra.contains("idle"));
  CHECK(r.model.extra["idle"]["freq"].get<double>() == Approx(car.idle_freq).epsilon(0.05));
  CHECK(r.model.extra["idle"]["sd"].get<double>() < 0.1 * car.idle_freq);
  // Without a single sample at rest there is no idle to record, and none is made up.
  std::vector<Sample> moving;
  for (const Sample& s : samples)
    if (s.speed > 1.0) moving.push_back(s);
  CHECK_FALSE(fit_gear_model(moving, {}).model.extra.contains("idle"));
}

TEST_CASE("estimator: a fit records the idle an engine is held at while the car rolls declutched") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  auto samples = sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kUrban, 1200.0, 1, 3));
  // The simulated engine falls to its standing idle declutched: no rolling idle is recorded.
  const FitResult plain = fit_gear_model(samples, {});
  REQUIRE(plain.model.extra.contains("idle"));
  CHECK_FALSE(plain.model.extra.contains("rolling_idle"));
  // The same drive with five rolls out of gear, the engine held at 1.2 x idle while the car slows from 20
  // m/s over 15 s (the flat revs a throttle kicker or an idle-up against stalling gives; at that speed
  // no gear's line passes near them).
  const double rolling = 1.2 * car.idle_freq;
  double t = samples.back().t;
  for (int roll = 0; roll < 5; ++roll) {
    t += 10.0;
    for (int k = 0; k < 15; ++k) {
      t += 1.0;
      samples.push_back({t, 20.0 - 0.4 * k, rolling * (1.0 + 0.01 * ((k % 3) - 1))});
    }
  }
  const FitResult r = fit_gear_model(samples, {});
  REQUIRE(r.model.extra.contains("rolling_idle"));
  CHECK(r.model.extra["rolling_idle"]["freq"].get<double>() == Approx(rolling).epsilon(0.02));
  CHECK(r.model.extra["rolling_idle"]["samples"].get<double>() >= 50);
}

TEST_CASE("estimator: a fit records how hard the car slows declutched at idle on the move") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  auto samples = sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kUrban, 1200.0, 1, 3));
  // The same drive with five stops braked from 12 m/s at 1.5 m/s^2 with the clutch out and the engine at
  // its idle (1 Hz, each after a gap of 10 s), and five rolls at 3 m/s^2 with the revs free at twice the
  // idle, which are no idle braking.
  double t = samples.back().t;
  for (int stop = 0; stop < 5; ++stop) {
    t += 10.0;
    for (int k = 1; k <= 8; ++k)
      samples.push_back({t += 1.0, 12.0 - 1.5 * k, car.idle_freq * (1.0 + 0.01 * ((k % 3) - 1))});
    t += 10.0;
    for (int k = 1; k <= 4; ++k)
      samples.push_back({t += 1.0, 20.0 - 3.0 * k, 2.0 * car.idle_freq});
  }
  const FitResult r = fit_gear_model(samples, {});
  REQUIRE(r.model.extra.contains("idle_braking"));
  const nlohmann::json& braking = r.model.extra["idle_braking"];
  INFO(braking.dump());
  CHECK(braking["accel"].get<double>() == Approx(-1.5).margin(0.15));
  CHECK(braking["seconds"].get<double>() >= 40.0);
  CHECK(braking["samples"].get<double>() >= 40.0);
  // Without a single sample at rest there is no idle, hence no idle braking.
  std::vector<Sample> moving;
  for (const Sample& s : samples)
    if (s.speed > 1.0) moving.push_back(s);
  CHECK_FALSE(fit_gear_model(moving, {}).model.extra.contains("idle_braking"));
}

TEST_CASE("estimator: the Etios logs record a rolling idle about a fifth above the standing idle") {
  // The Etios holds its engine about a fifth above its standing idle rolling declutched.
  const auto etios = read_etios("drive");
  if (etios.empty()) GEARPULSE_SKIP_TEST("Etios logs not found under " << test::real_data_dir());
  const FitResult e = fit_gear_model(etios, {});
  REQUIRE(e.model.extra.contains("rolling_idle"));
  const double ratio =
      e.model.extra["rolling_idle"]["freq"].get<double>() / e.model.extra["idle"]["freq"].get<double>();
  CHECK(ratio > 1.1);
  CHECK(ratio < 1.35);
}

TEST_CASE("estimator: a fit records the revs each gear is driven at") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  sim::DriveOptions options;
  options.style = sim::DrivingStyle::kMixed;
  options.duration = 2400.0;
  options.seed = 5;
  const sim::Drive drive = sim::simulate_drive(car, options);
  const FitResult r = fit_gear_model(sim::to_samples(sim::observe(drive, {})), {});
  REQUIRE(r.model.gears.size() == car.theta.size());
  REQUIRE(r.model.extra.contains("revs"));
  const nlohmann::json& revs = r.model.extra["revs"];
  REQUIRE(revs.size() == car.theta.size());
  // Against the truth: ln(engine frequency) over the seconds each gear was engaged while moving. First
  // gear's entry also holds the crawl on a slipping clutch and a car rolling out of gear at walking pace
  // (first gear at those revs explains the speed, so the synthesis has to weigh them as first gear): its
  // revs lie between the idle and those engaged.
  for (std::size_t g = 0; g < car.theta.size(); ++g) {
    double sum = 0.0, sum2 = 0.0, n = 0.0;
    for (const sim::TruthSample& s : drive.truth) {
      if (s.gear != static_cast<int>(g) + 1 || s.clutch != sim::Clutch::kEngaged || s.speed < 1.0) continue;
      sum += std::log(s.freq);
      sum2 += std::log(s.freq) * std::log(s.freq);
      ++n;
    }
    REQUIRE(n > 10.0);
    const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
    const double mean_log = revs[g]["mean_log"].get<double>(), sd_log = revs[g]["sd_log"].get<double>();
    INFO("gear " << g + 1 << ": true ln(freq) " << mean << " +- " << sd << " over " << n << " s; fit "
                 << mean_log << " +- " << sd_log);
    CHECK(revs[g]["samples"].get<double>() > 0.5 * n);
    if (g == 0) {
      CHECK(mean_log > std::log(car.idle_freq));
      CHECK(mean_log < mean + 0.05);
      continue;
    }
    CHECK(mean_log == Approx(mean).margin(0.05));
    CHECK(sd_log == Approx(sd).margin(0.08));
  }
  // A log with no gear ladder records no revs of gears it does not have.
  const auto cvt = sim::to_samples(
      sim::simulate_observations(sim::vehicle_preset("cvt"), sim::DrivingStyle::kMixed, 1200.0, 1, 3));
  const FitResult none = fit_gear_model(cvt, {});
  CHECK(none.model.gears.empty());
  CHECK_FALSE(none.model.extra.contains("revs"));
}

TEST_CASE("estimator: a polled log's fit records its launches from rest, a 1 Hz log's none") {
  // OBD rows, each value polled once a second at its own instant within the first half second.
  sim::ObservationOptions obd;
  obd.obd = true;
  obd.period = 0.5;
  obd.obd_refresh = 1.0;
  obd.obd_skew = 0.5;
  obd.seed = 9;
  for (const char* name : {"bmw-520i", "van-6"}) {
    const sim::Vehicle car = sim::vehicle_preset(name);
    const FitResult r = fit_gear_model(
        sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kMixed, 2400.0, 1, 2, obd)), {});
    INFO(name << ": " << serialize_model(r.model));
    REQUIRE(r.model.extra.contains("launch_gears"));
    const nlohmann::json& launches = r.model.extra["launch_gears"];
    CHECK(launches["base"].get<double>() == Approx(r.model.gears[0].theta));
    REQUIRE(launches["counts"].size() == 5);
    double total = 0.0, below = 0.0;
    for (std::size_t k = 0; k < 5; ++k) {
      total += launches["counts"][k].get<double>();
      if (k > 0) below += launches["counts"][k].get<double>();
    }
    CHECK(total >= 3.0);
    // A ladder that starts at first gear reads no launch passing a gear below it; one that lacks first
    // gear reads some.
    const bool has_first = std::abs(std::log(r.model.gears[0].theta / car.theta[0])) < 0.1;
    if (has_first)
      CHECK(below == 0.0);
    else
      CHECK(below >= 1.0);
  }
  // The daemon's 1 Hz pairs: each drive counts its own launches at 10 Hz, the fit records none.
  const sim::Vehicle car = sim::vehicle_preset("van-6");
  const FitResult one_hz = fit_gear_model(
      sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kMixed, 2400.0, 1, 2)), {});
  CHECK_FALSE(one_hz.model.extra.contains("launch_gears"));
}
