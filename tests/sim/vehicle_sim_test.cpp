#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;

TEST_CASE("sim: same seed gives the same drive and engaged samples lie on their gear line") {
  const sim::Vehicle car = sim::bmw_520i();
  const std::uint64_t seed = 11;
  std::printf("sim seed %llu\n", static_cast<unsigned long long>(seed));
  const sim::Drive a = sim::simulate_drive(car, {sim::DrivingStyle::kMixed, 1200.0, 1.0, seed});
  const sim::Drive b = sim::simulate_drive(car, {sim::DrivingStyle::kMixed, 1200.0, 1.0, seed});
  REQUIRE(a.truth.size() == 1201);
  REQUIRE(b.truth.size() == a.truth.size());
  int engaged = 0;
  int standing = 0;
  for (std::size_t k = 0; k < a.truth.size(); ++k) {
    const sim::TruthSample& t = a.truth[k];
    CHECK(t.speed == b.truth[k].speed);
    CHECK(t.speed >= 0.0);
    if (t.clutch == sim::Clutch::kEngaged) {
      REQUIRE(t.gear >= 1);
      REQUIRE(t.gear <= 5);
      CHECK(t.speed == Approx(car.theta[static_cast<std::size_t>(t.gear - 1)] * t.freq).epsilon(1e-6));
      ++engaged;
    }
    if (t.speed == 0.0) {
      ++standing;
      CHECK(t.gear == 0);
      CHECK(t.freq == Approx(car.idle_freq).epsilon(0.05));
    }
  }
  CHECK(engaged > 600);
  CHECK(standing > 10);
}

TEST_CASE("sim: the output grid does not change the drive") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  const sim::Drive coarse = sim::simulate_drive(car, {sim::DrivingStyle::kUrban, 300.0, 1.0, 5});
  const sim::Drive fine = sim::simulate_drive(car, {sim::DrivingStyle::kUrban, 300.0, 0.01, 5});
  REQUIRE(fine.truth.size() == 30001);
  for (std::size_t k = 0; k < coarse.truth.size(); ++k) {
    CHECK(fine.truth[k * 100].speed == Approx(coarse.truth[k].speed).margin(1e-9));
    CHECK(sim::truth_at(fine, static_cast<double>(k)).freq == Approx(coarse.truth[k].freq).margin(1e-9));
  }
}

TEST_CASE("sim: GPS observations are noisy and non-negative and a band floor hides low frequencies") {
  const sim::Vehicle car = sim::bmw_520i();
  const sim::Drive drive = sim::simulate_drive(car, {sim::DrivingStyle::kUrban, 600.0, 1.0, 3});
  sim::ObservationOptions o;
  o.freq_floor = 50.0;
  const auto obs = sim::observe(drive, o);
  REQUIRE(obs.size() == drive.truth.size());
  double sq = 0.0;
  int moving = 0;
  for (const auto& ob : obs) {
    CHECK(ob.speed >= 0.0);
    if (ob.truth.freq < 50.0) CHECK(std::isnan(ob.freq));
    if (ob.truth.speed > 3.0) {
      sq += (ob.speed - ob.truth.speed) * (ob.speed - ob.truth.speed);
      ++moving;
    }
  }
  REQUIRE(moving > 50);
  CHECK(std::sqrt(sq / moving) == Approx(o.sigma_speed).epsilon(0.3));
}

TEST_CASE("sim: OBD mode gives integer km/h and repeated rows") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  const sim::Drive drive = sim::simulate_drive(car, {sim::DrivingStyle::kUrban, 600.0, 0.5, 4});
  sim::ObservationOptions o;
  o.obd = true;
  o.period = 0.5;
  const auto obs = sim::observe(drive, o);
  int repeats = 0;
  for (std::size_t k = 1; k < obs.size(); ++k) {
    if (std::isnan(obs[k].speed)) continue;
    const double kmh = obs[k].speed * 3.6;
    CHECK(std::abs(kmh - std::round(kmh)) < 1e-9);
    if (obs[k].speed == obs[k - 1].speed && obs[k].freq == obs[k - 1].freq) ++repeats;
  }
  CHECK(repeats > static_cast<int>(obs.size()) / 3);
}

TEST_CASE("sim: CVT and presets are valid and unknown names are rejected") {
  for (const sim::Vehicle& v : sim::vehicle_presets()) {
    const sim::Drive d = sim::simulate_drive(v, {sim::DrivingStyle::kMixed, 120.0, 1.0, 1});
    CHECK(d.truth.size() == 121);
  }
  CHECK_THROWS_AS(sim::vehicle_preset("no-such-car"), std::invalid_argument);
  CHECK_THROWS_AS(sim::parse_style("rally"), std::invalid_argument);
}

TEST_CASE("sim: random vehicles are plausible manual cars and repeat by seed") {
  std::set<int> gear_counts;
  double lowest_idle = 1e9, highest_idle = 0.0;
  for (std::uint64_t seed = 1; seed <= 60; ++seed) {
    const sim::Vehicle v = sim::random_vehicle(seed);
    INFO(v.name);
    CHECK(v.name == "random-" + std::to_string(seed));
    REQUIRE(v.gears() >= 4);
    REQUIRE(v.gears() <= 7);
    gear_counts.insert(v.gears());
    // A progressive ladder: every step a real gearbox could have, none wider than the one below it.
    for (int i = 1; i < v.gears(); ++i) {
      const double step = v.theta[static_cast<std::size_t>(i)] / v.theta[static_cast<std::size_t>(i - 1)];
      CHECK(step > 1.1);
      CHECK(step < 2.3);
      if (i > 1)
        CHECK(step <= v.theta[static_cast<std::size_t>(i - 1)] / v.theta[static_cast<std::size_t>(i - 2)]);
    }
    const double spread = v.theta.back() / v.theta.front();
    CHECK(spread >= 3.0);
    CHECK(spread <= 5.2);
    // Revs in the order a driver uses them.
    CHECK(v.idle_freq * 1.3 < v.downshift_freq);
    CHECK(v.downshift_freq < v.upshift_freq);
    CHECK(v.upshift_freq < v.max_freq);
    // Top gear at idle revs: a road car's 15-40 km/h, whatever multiple of the crank the component is.
    const double top_at_idle_kmh = v.theta.back() * v.idle_freq * 3.6;
    CHECK(top_at_idle_kmh > 15.0);
    CHECK(top_at_idle_kmh < 40.0);
    lowest_idle = std::min(lowest_idle, v.idle_freq);
    highest_idle = std::max(highest_idle, v.idle_freq);
    const sim::Drive d = sim::simulate_drive(v, {sim::DrivingStyle::kMixed, 300.0, 1.0, seed});
    CHECK(d.truth.size() == 301);
    // Same seed, same vehicle.
    CHECK(sim::random_vehicle(seed).theta == v.theta);
  }
  CHECK(gear_counts.size() == 4);  // 4, 5, 6 and 7 gears all drawn
  CHECK(lowest_idle < 16.0);       // the crank ...
  CHECK(highest_idle > 45.0);      // ... and firing frequencies several times higher
  CHECK(sim::random_vehicle(1).theta != sim::random_vehicle(2).theta);
}

TEST_CASE("sim: the wide family spans more gearboxes and engines, drivable, and repeats by seed") {
  std::set<int> gear_counts;
  double widest = 0.0, closest = 1e9;
  for (std::uint64_t seed = 1; seed <= 80; ++seed) {
    const sim::Vehicle v = sim::wide_vehicle(seed);
    INFO(v.name);
    CHECK(v.name == "wide-family-" + std::to_string(seed));
    REQUIRE(v.gears() >= 3);
    REQUIRE(v.gears() <= 9);
    gear_counts.insert(v.gears());
    for (int i = 1; i < v.gears(); ++i) {
      const double step = v.theta[static_cast<std::size_t>(i)] / v.theta[static_cast<std::size_t>(i - 1)];
      CHECK(step >= 1.07 - 1e-9);  // what a fit can tell apart (it takes 1.06)
      CHECK(step <= 2.5 + 1e-9);
      closest = std::min(closest, step);
    }
    widest = std::max(widest, v.theta.back() / v.theta.front());
    CHECK(v.idle_freq * 1.3 < v.downshift_freq);
    CHECK(v.downshift_freq < v.upshift_freq);
    CHECK(v.upshift_freq < v.max_freq);
    // The rev limit over the idle, whatever multiple of the crank the component is: an engine's band.
    CHECK(v.max_freq / v.idle_freq > 4.0);
    const double top_at_idle_kmh = v.theta.back() * v.idle_freq * 3.6;
    CHECK(top_at_idle_kmh > 15.0);
    CHECK(top_at_idle_kmh < 60.0);
    const sim::Drive d = sim::simulate_drive(v, {sim::DrivingStyle::kMixed, 300.0, 1.0, seed});
    CHECK(d.truth.size() == 301);
    CHECK(sim::wide_vehicle(seed).theta == v.theta);
  }
  CHECK(gear_counts.size() == 7);  // 3 to 9 gears all drawn
  CHECK(widest > 6.0);             // a crawler first
  CHECK(closest < 1.12);           // two close top gears
  CHECK(sim::wide_vehicle(1).theta != sim::random_vehicle(1).theta);
}

TEST_CASE("sim: the driver does not hunt between two gears") {
  // An upshift followed within a few seconds by a downshift back into the gear just left, at about the
  // same speed, is hunting: the driver shifted up into a gear too low on revs. Braking for a stop after an
  // upshift (a real speed drop) is not counted.
  for (const char* name : {"van-6", "hatch-5", "wide-4"}) {
    const sim::Vehicle car = sim::vehicle_preset(name);
    for (auto style : {sim::DrivingStyle::kUrban, sim::DrivingStyle::kTrafficJam}) {
      const sim::Drive drive = sim::simulate_drive(car, {style, 2400.0, 0.05, 3});
      int upshifts = 0;
      int hunts = 0;
      int engaged = 0;
      int left = 0;
      double up_time = -1e9;
      double up_speed = 0.0;
      for (const sim::TruthSample& t : drive.truth) {
        if (t.clutch != sim::Clutch::kEngaged || t.gear == engaged) continue;
        if (t.gear > engaged && engaged > 0) {
          ++upshifts;
          left = engaged;
          up_time = t.t;
          up_speed = t.speed;
        } else if (t.gear == left && t.t - up_time < 4.0 && t.speed > 0.97 * up_speed) {
          ++hunts;
        }
        engaged = t.gear;
      }
      INFO(name << " " << sim::style_name(style) << ": " << hunts << " hunts in " << upshifts << " upshifts");
      CHECK(upshifts > 20);
      CHECK(hunts * 20 <= upshifts);
    }
  }
}

TEST_CASE("sim: a cold engine idles high at the start and settles to its warm idle") {
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  sim::DriveOptions options{sim::DrivingStyle::kUrban, 1800.0, 1.0, 5};
  options.cold_start = 0.5;
  const sim::Drive cold = sim::simulate_drive(car, options);
  // The car stands a few seconds before it moves off: the idle then is the cold one.
  REQUIRE(cold.truth[1].speed == 0.0);
  CHECK(cold.truth[1].freq == Approx(1.5 * car.idle_freq).epsilon(0.05));
  // Standing after ten minutes: the warm idle.
  int late_standing = 0;
  for (const sim::TruthSample& t : cold.truth) {
    if (t.t < 600.0 || t.speed > 0.0) continue;
    ++late_standing;
    CHECK(t.freq == Approx(car.idle_freq).epsilon(0.05));
  }
  CHECK(late_standing > 10);
  options.cold_start = -0.1;
  CHECK_THROWS_AS(sim::simulate_drive(car, options), std::invalid_argument);
  options.cold_start = 0.5;
  options.warm_up = 0.0;
  CHECK_THROWS_AS(sim::simulate_drive(car, options), std::invalid_argument);
}

TEST_CASE("sim: braking drivers skip a gear down only when asked to") {
  // Counts downshifts that skip a gear: the gear engaged after the clutch two or more below the one before.
  const auto skips = [](double share) {
    sim::DriveOptions options;
    options.style = sim::DrivingStyle::kUrban;
    options.duration = 1800.0;
    options.dt = 0.1;
    options.seed = 21;
    options.skip_downshift = share;
    const sim::Drive drive = sim::simulate_drive(sim::vehicle_preset("hatch-5"), options);
    int last = 0, count = 0;
    for (const sim::TruthSample& t : drive.truth) {
      if (t.gear == 0) continue;
      if (last > 0 && t.gear <= last - 2) ++count;
      last = t.gear;
    }
    return count;
  };
  // Without the option a gear is skipped only when a coast ends in the gear its speed needs.
  const int unasked = skips(0.0);
  CHECK(skips(1.0) >= unasked + 5);
}
