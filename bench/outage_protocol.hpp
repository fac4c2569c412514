#pragma once
// The outage protocol shared by the synthesis benches (bench_real_logs on logged drives, bench_synth_sim
// on simulated ones): 60 s GPS outages, the first 120 s after a drive starts, then one every 180 s; the
// hindsight choice (a gear, or standing); quantiles of the errors.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "core/gear_model.hpp"

namespace gearpulse::bench {

// The CSV logs in `dir` whose names begin with `prefix`, sorted (none when `dir` is missing).
inline std::vector<std::filesystem::path> csv_logs(const std::filesystem::path& dir,
                                                   const std::string& prefix) {
  std::vector<std::filesystem::path> paths;
  if (!std::filesystem::exists(dir)) return paths;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().extension() == ".csv" && e.path().filename().string().rfind(prefix, 0) == 0)
      paths.push_back(e.path());
  std::sort(paths.begin(), paths.end());
  return paths;
}

inline constexpr double kOutageStart = 120.0;   // s after the drive starts
inline constexpr double kOutagePeriod = 180.0;  // s between outage starts
inline constexpr double kOutageLength = 60.0;   // s
inline constexpr double kMsToKmh = 3.6;

// Whether a sample `t_rel` seconds after the drive's start falls inside an outage.
inline bool in_outage(double t_rel) {
  if (t_rel < kOutageStart) return false;
  return std::fmod(t_rel - kOutageStart, kOutagePeriod) < kOutageLength;
}

// Index of the gear whose theta x freq is closest to `speed` (the gear chosen with hindsight), -1 when
// the model has none.
inline int nearest_gear(const GearModel& m, double speed, double freq) {
  int best = -1;
  double err = 0.0;
  for (std::size_t i = 0; i < m.gears.size(); ++i) {
    const double e = std::abs(m.gears[i].theta * freq - speed);
    if (best < 0 || e < err) best = static_cast<int>(i), err = e;
  }
  return best;
}

// The speed chosen with hindsight: theta x freq of the nearest gear, or 0 when the truth is closer to
// standing (at rest the right choice is no gear at all, which no theta x idle revs can give).
inline double hindsight_speed(const GearModel& m, double speed, double freq) {
  const int g = nearest_gear(m, speed, freq);
  const double geared = g < 0 ? 0.0 : m.gears[static_cast<std::size_t>(g)].theta * freq;
  return std::abs(geared - speed) < speed ? geared : 0.0;
}

// Linear-interpolated quantile q of v, NaN when v is empty.
inline double quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<std::size_t>(pos);
  const std::size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

}  // namespace gearpulse::bench
