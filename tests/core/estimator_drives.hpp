#pragma once
// The drives the estimator's tests fit: simulated ones, and the real logs beside the source tree (empty
// when they are absent; a test that needs them skips).
#include <catch2/catch.hpp>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "core/gear_model.hpp"
#include "core/sample.hpp"
#include "core/sample_io.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::test {

inline std::vector<Sample> simulate(const sim::Vehicle& car, sim::DrivingStyle style, double duration,
                                    int drives, std::uint64_t seed) {
  std::printf("estimator sim: %s %s seed %llu\n", car.name.c_str(),
              std::string(sim::style_name(style)).c_str(), static_cast<unsigned long long>(seed));
  return sim::to_samples(sim::simulate_observations(car, style, duration, drives, seed));
}

inline void check_ordered(const GearModel& model) {
  for (std::size_t i = 1; i < model.gears.size(); ++i)
    CHECK(model.gears[i].theta > model.gears[i - 1].theta);
  for (const Gear& g : model.gears) {
    CHECK(g.theta > 0.0);
    CHECK(g.weight > 0.0);
    CHECK(g.std_error > 0.0);
  }
}

inline std::vector<Sample> read_real(const std::string& relative, TorqueSpeed speed = TorqueSpeed::kAuto) {
  const std::string path = (real_data_dir() / relative).string();
  std::ifstream in(path);
  if (!in) return {};
  ReadOptions options;
  options.torque_speed = speed;
  return read_samples(in, path, options).samples;
}

// The Etios logs PREFIX1.csv .. PREFIX13.csv pooled (empty when the real logs are absent).
inline std::vector<Sample> read_etios(const std::string& prefix) {
  std::vector<Sample> all;
  for (int d = 1; d <= 13; ++d) {
    const auto part = read_real("carloop-etios/" + prefix + std::to_string(d) + ".csv");
    all.insert(all.end(), part.begin(), part.end());
  }
  return all;
}

}  // namespace gearpulse::test
