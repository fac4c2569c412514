// The estimator's gear ladder from simulated drives: paper and auto mode, the noise levels, first gears
// seen seldom, ladders that are none (a CVT, zero speed), and the options it refuses. The fit's numerics
// are in estimator_numerics_test.cpp, logs as loggers write them in estimator_logs_test.cpp, what a fit
// records of the driver in estimator_habits_test.cpp.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

#include "core/estimator.hpp"
#include "tests/core/estimator_drives.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;
using gearpulse::test::check_ordered;
using gearpulse::test::simulate;

TEST_CASE("estimator: paper mode recovers the BMW 520i within 1 percent") {
  const sim::Vehicle car = sim::bmw_520i();
  const auto samples = simulate(car, sim::DrivingStyle::kMixed, 1200.0, 2, 7);
  FitOptions options;
  options.ratios = {1.25, 1.35, 1.50, 1.7};  // Table 2, top gear down
  const FitResult fit = fit_gear_model(samples, options);
  CHECK(fit.model.method == "paper");
  REQUIRE(fit.model.gears.size() == 5);
  for (std::size_t i = 0; i < 5; ++i)
    CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.01));
  check_ordered(fit.model);
}

TEST_CASE("estimator: auto mode finds gear count and every theta within 0.5 percent") {
  struct Case {
    const char* vehicle;
    sim::DrivingStyle style;
    std::uint64_t seed;
  };
  // 4 to 7 gears, close and wide ratios, every driving style; 40 min at 1 Hz each.
  const Case cases[] = {
      {"bmw-520i", sim::DrivingStyle::kMixed, 1},       {"hatch-5", sim::DrivingStyle::kUrban, 1},
      {"close-6", sim::DrivingStyle::kMixed, 1},        {"wide-4", sim::DrivingStyle::kMixed, 1},
      {"compact-4", sim::DrivingStyle::kTrafficJam, 1}, {"sport-7", sim::DrivingStyle::kUrban, 1},
      {"hatch-5", sim::DrivingStyle::kHighway, 1},      {"van-6", sim::DrivingStyle::kTrafficJam, 1}};
  for (const Case& c : cases) {
    const sim::Vehicle car = sim::vehicle_preset(c.vehicle);
    const FitResult fit = fit_gear_model(simulate(car, c.style, 2400.0, 1, c.seed), {});
    INFO(c.vehicle << " " << sim::style_name(c.style));
    CHECK(fit.model.method == "auto");
    REQUIRE(fit.model.gears.size() == car.theta.size());
    for (std::size_t i = 0; i < car.theta.size(); ++i)
      CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.005));
    check_ordered(fit.model);
    CHECK(fit.model.sigma_speed > 0.0);
    CHECK(fit.model.extra.contains("clutch_out"));
  }
}

TEST_CASE("estimator: the same drive seen many times gives the ladder it gives once") {
  // A week of one commute is close to one drive seen again and again: the ladder must not depend on how
  // often. `times` copies of the drive, each on its clock from 0 as `gearpulse fit` joins logs, or each
  // `shift` seconds after the one before (distinct records of the same driving).
  const auto repeated = [](const std::vector<Sample>& drive, int times, double shift) {
    std::vector<Sample> all;
    all.reserve(drive.size() * static_cast<std::size_t>(times));
    for (int i = 0; i < times; ++i)
      for (Sample s : drive) {
        s.t += shift * i;
        all.push_back(s);
      }
    return all;
  };
  const auto thetas = [](const GearModel& m) {
    std::vector<double> out;
    for (const Gear& g : m.gears)
      out.push_back(g.theta);
    return out;
  };
  struct Case {
    sim::DrivingStyle style;
    std::uint64_t seed;
    int times;
    double shift;
  };
  // Copies on one clock: urban seed 2 at 20 gained a sixth gear (a copied clutch-slip bump passed the
  // count floors). Copies in sequence: 1000 of a drive of exactly 2400 samples, taken every 150th sample
  // for model selection, kept 3 of its 5 gears.
  const Case cases[] = {{sim::DrivingStyle::kUrban, 1, 20, 0.0},
                        {sim::DrivingStyle::kUrban, 2, 20, 0.0},
                        {sim::DrivingStyle::kMixed, 1, 1000, 2400.0}};
  for (const Case& c : cases) {
    std::vector<Sample> drive = simulate(sim::vehicle_preset("bmw-520i"), c.style, 2400.0, 1, c.seed);
    drive.resize(std::min<std::size_t>(drive.size(), 2400));
    const FitResult once = fit_gear_model(drive, {});
    const FitResult often = fit_gear_model(repeated(drive, c.times, c.shift), {});
    INFO(sim::style_name(c.style) << " seed " << c.seed << " x" << c.times);
    REQUIRE(once.model.gears.size() == 5);
    REQUIRE(often.model.gears.size() == once.model.gears.size());
    const auto a = thetas(once.model), b = thetas(often.model);
    for (std::size_t i = 0; i < a.size(); ++i)
      CHECK(b[i] == Approx(a[i]).epsilon(0.002));
  }
}

TEST_CASE("estimator: both noise levels are estimated and neither sticks at zero") {
  // The simulator's truth: sigma_v 0.05 m/s (GPS Doppler), sigma_s 0.2 Hz (tracker). A fit that lets one
  // noise level collapse makes every gear line as wide as the top gear's.
  for (const char* name : {"hatch-5", "van-6"}) {
    const sim::Vehicle car = sim::vehicle_preset(name);
    const FitResult fit = fit_gear_model(simulate(car, sim::DrivingStyle::kMixed, 2400.0, 1, 1), {});
    INFO(name << ": sigma_freq " << fit.model.sigma_freq << " sigma_speed " << fit.model.sigma_speed);
    REQUIRE(fit.model.gears.size() == car.theta.size());
    CHECK(fit.model.sigma_freq == Approx(0.2).epsilon(0.25));
    CHECK(fit.model.sigma_speed == Approx(0.05).epsilon(0.35));
  }
}

TEST_CASE("estimator: a first gear seen on a few launches of a highway drive is found") {
  // 40 min mostly at highway speed: first gear is engaged for a second or two on each of a few launches
  // in town, a dozen samples at 1 Hz, well under one percent of the moving samples.
  for (const char* name : {"wide-4", "compact-4", "hatch-5"}) {
    const sim::Vehicle car = sim::vehicle_preset(name);
    for (std::uint64_t seed = 1; seed <= 3; ++seed) {
      const auto observed = sim::simulate_observations(car, sim::DrivingStyle::kHighway, 2400.0, 1, seed);
      int first = 0;
      for (const auto& o : observed)
        first += o.truth.clutch == sim::Clutch::kEngaged && o.truth.gear == 1 ? 1 : 0;
      INFO(name << " seed " << seed << ": first gear engaged in " << first << " samples");
      REQUIRE(first <= 25);
      if (first < 8) continue;
      const FitResult fit = fit_gear_model(sim::to_samples(observed), {});
      REQUIRE(fit.model.gears.size() == car.theta.size());
      // A dozen samples pin theta_1 to about half a percent (its standard error); the others are tight.
      CHECK(std::abs(fit.model.gears[0].theta - car.theta[0]) < 3.0 * fit.model.gears[0].std_error);
      CHECK(fit.model.gears[0].theta == Approx(car.theta[0]).epsilon(0.015));
      for (std::size_t i = 1; i < car.theta.size(); ++i)
        CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.005));
    }
  }
}

TEST_CASE("estimator: a first gear too little driven for the count is taken where the ladder lacks it") {
  // 40 min mostly at highway speed: on some seeds (here seed 4) first gear is engaged on so few 1 Hz
  // samples that BIC drops it, though a ladder holding it passed every check. The ladder without it carries
  // the car at idle faster than first gear can (wide-4's second gear: 2.8 m/s), so the fit takes the larger
  // ladder; no fit records gears below its ladder.
  const sim::Vehicle car = sim::vehicle_preset("wide-4");
  for (std::uint64_t seed = 1; seed <= 6; ++seed) {
    const auto samples =
        sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kHighway, 2400.0, 1, seed));
    const FitResult fit = fit_gear_model(samples, {});
    INFO("seed " << seed << ": " << fit.model.gears.size() << " gears, extra " << fit.model.extra.dump());
    REQUIRE(fit.model.gears.size() == car.theta.size());
    CHECK_FALSE(fit.model.extra.contains("lower_gears"));
    CHECK(fit.model.gears[0].theta == Approx(car.theta[0]).epsilon(0.015));
  }
}

TEST_CASE("estimator: a first gear held for less than a 0.5 Hz log's interval is found") {
  // Logged every 2 s, a launch shows first gear on one sample, rarely on two in a row: the cluster has
  // hardly any sample that agrees with a neighbour, which the ladder check otherwise relies on.
  sim::ObservationOptions every_2s;
  every_2s.period = 2.0;
  for (const char* name : {"bmw-520i", "close-6", "sport-7", "compact-4"}) {
    const sim::Vehicle car = sim::vehicle_preset(name);
    const auto observed = sim::simulate_observations(car, sim::DrivingStyle::kMixed, 2400.0, 1, 2, every_2s);
    int first = 0;
    int first_in_a_row = 0;
    for (std::size_t k = 0; k < observed.size(); ++k) {
      auto in_first = [&](std::size_t j) {
        return observed[j].truth.clutch == sim::Clutch::kEngaged && observed[j].truth.gear == 1;
      };
      if (!in_first(k)) continue;
      ++first;
      first_in_a_row += (k > 0 && in_first(k - 1)) || (k + 1 < observed.size() && in_first(k + 1)) ? 1 : 0;
    }
    INFO(name << ": first gear on " << first << " samples, " << first_in_a_row << " beside another");
    REQUIRE(first >= 8);
    REQUIRE(first_in_a_row < 6);
    const FitResult fit = fit_gear_model(sim::to_samples(observed), {});
    REQUIRE(fit.model.gears.size() == car.theta.size());
    check_ordered(fit.model);
    CHECK(fit.model.gears[0].theta == Approx(car.theta[0]).epsilon(0.02));
    for (std::size_t i = 1; i < car.theta.size(); ++i)
      CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.01));
  }
}

TEST_CASE("estimator: a ladder that lacks first gear at OBD polls 1 s apart takes it from a larger one") {
  // OBD rows, each value polled once a second at its own instant within the first half second: a launch's
  // pairs, polled apart while the car gains 2-3 m/s^2, spread first gear's ratios, and the gear gains less
  // than BIC asks. On these drives the ladder without first gear carries the car at idle faster than first
  // gear can, and a plausible ladder met on the way down held it.
  struct Drive {
    const char* car;
    std::uint64_t seed;
  };
  for (const Drive d : {Drive{"bmw-520i", 2}, Drive{"bmw-520i", 4}, Drive{"close-6", 3}, Drive{"wide-4", 3},
                        Drive{"sport-7", 2}, Drive{"compact-4", 4}}) {
    const sim::Vehicle car = sim::vehicle_preset(d.car);
    sim::ObservationOptions obd;
    obd.obd = true;
    obd.period = 0.5;
    obd.obd_refresh = 1.0;
    obd.obd_skew = 0.5;
    obd.seed = d.seed + 7;
    const FitResult fit = fit_gear_model(
        sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kMixed, 2400.0, 1, d.seed, obd)),
        {});
    INFO(d.car << " seed " << d.seed << ": " << serialize_model(fit.model));
    REQUIRE(fit.model.gears.size() == car.theta.size());
    check_ordered(fit.model);
    CHECK(fit.model.gears[0].theta == Approx(car.theta[0]).epsilon(0.05));
    for (std::size_t i = 1; i < car.theta.size(); ++i)
      CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.02));
  }
}

TEST_CASE(
    "estimator: a motorcycle's ladder narrower than any gearbox takes its first gear from a larger one") {
  // A motorcycle (wide-family-501: 5 close gears, spread 2.42, first gear at idle 2.9 m/s) logged by OBD
  // polls 1 s apart: BIC drops first gear, and the four gears left span about 1.6x, less than any road
  // vehicle's gearbox (kMinSpread). Its first gear carries it at idle faster than a car's can
  // (kFirstGearIdleSpeed), so only the spread tells that the ladder lacks it; a plausible ladder met on the
  // way down held it.
  const sim::Vehicle car = sim::wide_vehicle(501);
  for (const std::uint64_t seed : {1, 2, 4}) {
    sim::ObservationOptions obd;
    obd.obd = true;
    obd.period = 0.5;
    obd.obd_refresh = 1.0;
    obd.obd_skew = 0.5;
    obd.seed = seed + 7;
    const FitResult fit = fit_gear_model(
        sim::to_samples(sim::simulate_observations(car, sim::DrivingStyle::kMixed, 2400.0, 1, seed, obd)),
        {});
    INFO("seed " << seed << ": " << serialize_model(fit.model));
    REQUIRE(fit.model.gears.size() == car.theta.size());
    check_ordered(fit.model);
    CHECK(fit.model.gears[0].theta == Approx(car.theta[0]).epsilon(0.02));
    for (std::size_t i = 1; i < car.theta.size(); ++i)
      CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.01));
  }
}

TEST_CASE("estimator: a log without stops or clutch-out samples still gets standard errors") {
  // Moving samples on three gear lines only: the standstill and clutch-out weights go to their bound,
  // which must not take the standard errors of theta with them.
  const double theta[3] = {0.13, 0.24, 0.35};
  std::mt19937_64 rng(21);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> freq(20.0, 45.0);
  std::vector<Sample> samples;
  for (int k = 0; k < 2400; ++k) {
    const double f = freq(rng);
    const int gear = (k / 20) % 3;  // 20 s in each gear
    samples.push_back({static_cast<double>(k), theta[gear] * f + 0.05 * noise(rng), f + 0.2 * noise(rng)});
  }
  const FitResult fit = fit_gear_model(samples, {});
  REQUIRE(fit.model.gears.size() == 3);
  for (std::size_t i = 0; i < 3; ++i) {
    const Gear& g = fit.model.gears[i];
    // About 800 samples a gear: theta to roughly 1e-4 (sqrt(0.35^2 0.2^2 + 0.05^2) / (sqrt(800) 33 Hz)).
    CHECK(g.std_error > 2e-5);
    CHECK(g.std_error < 2e-4);
    CHECK(std::abs(g.theta - theta[i]) < 4.0 * g.std_error);
  }
}

TEST_CASE("estimator: a CVT has no gear ladder") {
  const sim::Vehicle cvt = sim::vehicle_preset("cvt");
  for (auto style : {sim::DrivingStyle::kMixed, sim::DrivingStyle::kTrafficJam}) {
    const FitResult fit = fit_gear_model(simulate(cvt, style, 2400.0, 1, 3), {});
    CHECK(fit.model.gears.empty());
    CHECK_FALSE(fit.model.reason.empty());
  }
}

TEST_CASE("estimator: a CVT's top ratio with a bump of its continuum beside it is no ladder") {
  // At speed a CVT holds its top ratio: one heavy cluster. A speed often driven at one engine speed leaves
  // a bump in the continuum below it, and the two made a two-gear ladder in these drives (the bump with
  // 0.6-2.9 % of the in-gear weight): a jam logged at 1 Hz, and OBD logs (1.8 s polls) of mixed, highway
  // and jam driving.
  const sim::Vehicle cvt = sim::vehicle_preset("cvt");
  struct Drive {
    sim::DrivingStyle style;
    std::uint64_t seed;
    bool obd;
  };
  for (const Drive d :
       {Drive{sim::DrivingStyle::kTrafficJam, 15, false}, Drive{sim::DrivingStyle::kTrafficJam, 20, false},
        Drive{sim::DrivingStyle::kMixed, 1, true}, Drive{sim::DrivingStyle::kHighway, 4, true},
        Drive{sim::DrivingStyle::kHighway, 13, true}, Drive{sim::DrivingStyle::kTrafficJam, 12, true}}) {
    sim::ObservationOptions options;
    if (d.obd) {
      options.obd = true;
      options.period = 0.5;
    }
    const FitResult fit = fit_gear_model(
        sim::to_samples(sim::simulate_observations(cvt, d.style, 2400.0, 1, d.seed, options)), {});
    INFO(sim::style_name(d.style) << " seed " << d.seed << (d.obd ? " OBD" : " 1 Hz") << ": "
                                  << serialize_model(fit.model));
    CHECK(fit.model.gears.empty());
    CHECK_FALSE(fit.model.reason.empty());
  }
}

TEST_CASE("estimator: top gear read on twice its engine frequency now and then is no gear") {
  // A frequency tracker that locks for a moment on the line at twice the engine's frequency reads top gear
  // at half its theta; wide-4's top gear (0.4500) then falls 7.5 % above second gear (0.2093), a step a
  // gearbox can have. Every 100th sample of top gear read so (every fourth of them with the sample after
  // it) made a fifth gear at 0.2254: most of those readings sit at twice their neighbours' frequency.
  const sim::Vehicle car = sim::vehicle_preset("wide-4");
  auto observed = sim::simulate_observations(car, sim::DrivingStyle::kMixed, 2400.0, 1, 1);
  int top = 0;
  for (std::size_t k = 0; k + 1 < observed.size(); ++k) {
    const sim::TruthSample& truth = observed[k].truth;
    if (truth.gear != car.gears() || truth.clutch != sim::Clutch::kEngaged || ++top % 100 != 0) continue;
    observed[k].freq *= 2.0;
    if (top % 400 == 0) observed[k + 1].freq *= 2.0;
  }
  const FitResult fit = fit_gear_model(sim::to_samples(observed), {});
  INFO(serialize_model(fit.model));
  REQUIRE(fit.model.gears.size() == car.theta.size());
  for (std::size_t i = 0; i < car.theta.size(); ++i)
    CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.005));
}

TEST_CASE("estimator: a drive in two gears gives both, the lighter with a tenth of the driving") {
  // A manual seen in only two gears (a stretch of fourth and fifth): the pair is a ladder when both are
  // driven, even one of them only a tenth of the time.
  std::mt19937_64 rng(11);
  std::normal_distribution<double> noise(0.0, 1.0);
  const double theta[2] = {0.45, 0.58};
  std::vector<Sample> drive;
  double t = 0.0;
  for (int stretch = 0; stretch < 40; ++stretch) {
    const int gear = stretch % 4 == 3 ? 0 : 1;  // fourth one stretch in four, each a third as long
    const int length = gear == 0 ? 15 : 45;
    for (int k = 0; k < length; ++k, t += 1.0) {
      const double f = 30.0 + 8.0 * std::sin(0.05 * t + stretch) + 0.3 * noise(rng);
      drive.push_back({t, theta[gear] * f + 0.05 * noise(rng), f});
    }
  }
  const FitResult fit = fit_gear_model(drive, {});
  INFO(serialize_model(fit.model));
  REQUIRE(fit.model.gears.size() == 2);
  CHECK(fit.model.gears[0].theta == Approx(theta[0]).epsilon(0.01));
  CHECK(fit.model.gears[1].theta == Approx(theta[1]).epsilon(0.01));
}

TEST_CASE("estimator: only zero speed or a single gear gives no model") {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<Sample> parked;
  std::vector<Sample> one_gear;
  for (int k = 0; k < 2000; ++k) {
    parked.push_back({static_cast<double>(k), std::abs(0.05 * noise(rng)), 13.3 + 0.2 * noise(rng)});
    const double f = 20.0 + 15.0 * std::sin(k * 0.01) + 0.2 * noise(rng);
    one_gear.push_back({static_cast<double>(k), 0.35 * f + 0.05 * noise(rng), f});
  }
  const FitResult a = fit_gear_model(parked, {});
  CHECK(a.model.gears.empty());
  CHECK_FALSE(a.model.reason.empty());
  const FitResult b = fit_gear_model(one_gear, {});
  CHECK(b.model.gears.empty());
  CHECK_FALSE(b.model.reason.empty());
  const FitResult c = fit_gear_model(std::vector<Sample>{}, {});
  CHECK(c.model.gears.empty());
}

TEST_CASE("estimator: unusable options are rejected") {
  const std::vector<Sample> none;
  FitOptions one;
  one.gears = 1;
  CHECK_THROWS_AS(fit_gear_model(none, one), std::invalid_argument);
  FitOptions many;
  many.gears = 13;
  CHECK_THROWS_AS(fit_gear_model(none, many), std::invalid_argument);
  FitOptions bad_ratio;
  bad_ratio.ratios = {1.3, 0.9};
  CHECK_THROWS_AS(fit_gear_model(none, bad_ratio), std::invalid_argument);
  bad_ratio.ratios = {1.3, std::nan("")};
  CHECK_THROWS_AS(fit_gear_model(none, bad_ratio), std::invalid_argument);
}
