#include <catch2/catch.hpp>

#include <cstdio>

#include "core/estimator.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;

namespace {

std::vector<Sample> simulate(const sim::Vehicle& car, sim::DrivingStyle style, double duration, int drives,
                             std::uint64_t seed) {
  std::printf("estimator sim: %s %s seed %llu\n", car.name.c_str(),
              std::string(sim::style_name(style)).c_str(), static_cast<unsigned long long>(seed));
  return sim::to_samples(sim::simulate_observations(car, style, duration, drives, seed));
}

}  // namespace

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
}

TEST_CASE("estimator: auto mode finds the BMW ladder without priors") {
  const sim::Vehicle car = sim::bmw_520i();
  const auto samples = simulate(car, sim::DrivingStyle::kMixed, 2400.0, 1, 21);
  const FitResult fit = fit_gear_model(samples, {});
  CHECK(fit.model.method == "auto");
  REQUIRE(fit.model.gears.size() == 5);
  for (std::size_t i = 0; i < 5; ++i)
    CHECK(fit.model.gears[i].theta == Approx(car.theta[i]).epsilon(0.005));
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
