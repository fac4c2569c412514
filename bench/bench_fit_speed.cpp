// Wall time of fit_gear_model (auto mode) on a week of 1 Hz samples: 604,800 simulated rows.
#include <chrono>
#include <cstdio>
#include <ctime>

#include "core/estimator.hpp"
#include "drivers/thread_slice_runner.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;

int main() {
  const std::uint64_t seed = 2024;
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  std::vector<Sample> samples;
  samples.reserve(604800);
  // Seven days alternating urban, mixed and jam days, one drive of 24 h each (continuous time).
  const sim::DrivingStyle styles[] = {sim::DrivingStyle::kUrban, sim::DrivingStyle::kMixed,
                                      sim::DrivingStyle::kTrafficJam};
  for (int day = 0; day < 7 && samples.size() < 604800; ++day) {
    auto part = sim::to_samples(sim::simulate_observations(car, styles[day % 3], 86400.0, 1, seed + day));
    for (Sample& s : part) {
      if (samples.size() == 604800) break;
      s.t += 86400.0 * day;
      samples.push_back(s);
    }
  }
  std::printf("bench_fit_speed: %zu samples (%s, seed %llu), 2 threads\n", samples.size(), car.name.c_str(),
              static_cast<unsigned long long>(seed));
  ThreadSliceRunner threads;
  FitOptions options;
  options.parallel = &threads;
  for (int run = 0; run < 3; ++run) {
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    const FitResult fit = fit_gear_model(samples, options);
    const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // CPU time of both threads: on a loaded machine wall time exceeds it / 2.
    const double cpu = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    std::printf("run %d: fit wall time %.3f s (cpu %.3f s), %zu gears:", run + 1, sec, cpu,
                fit.model.gears.size());
    for (const Gear& g : fit.model.gears)
      std::printf(" %.5f", g.theta);
    std::printf("\n");
  }
  return 0;
}
