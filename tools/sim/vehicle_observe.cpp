// Observation models: GPS Doppler speed and tracked frequency with white noise (paper eqs. (1)-(2)), or an
// OBD logger's integer km/h and rpm polled round-robin at skewed instants with repeated rows.
#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::sim {
namespace {

double band_limited(double observed, double truth, const ObservationOptions& o) {
  if (o.freq_floor > 0.0 && truth < o.freq_floor) return kMissing;
  if (o.freq_ceiling > 0.0 && truth > o.freq_ceiling) return kMissing;
  return observed;
}

std::vector<Observation> observe_gps(const Drive& drive, const ObservationOptions& o, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<Observation> out;
  const double end = drive.truth.empty() ? 0.0 : drive.truth.back().t;
  for (double t = 0.0; t <= end + 1e-9; t += o.period) {
    Observation ob;
    ob.truth = truth_at(drive, t);
    ob.speed = std::max(0.0, ob.truth.speed + o.sigma_speed * noise(rng));
    ob.freq = band_limited(ob.truth.freq + o.sigma_freq * noise(rng), ob.truth.freq, o);
    out.push_back(ob);
  }
  return out;
}

std::vector<Observation> observe_obd(const Drive& drive, const ObservationOptions& o, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Observation> out;
  const double end = drive.truth.empty() ? 0.0 : drive.truth.back().t;
  // Each polling round reads speed and rpm once, each at its own instant inside the round.
  double round_start = 0.0;
  double speed_poll = o.obd_skew * unit(rng);
  double rpm_poll = o.obd_skew * unit(rng);
  double speed = kMissing;
  double freq = kMissing;
  for (double t = 0.0; t <= end + 1e-9; t += o.period) {
    while (round_start + speed_poll <= t || round_start + rpm_poll <= t) {
      if (round_start + speed_poll <= t && speed_poll >= 0.0) {
        const TruthSample s = truth_at(drive, round_start + speed_poll);
        speed = std::round(s.speed * 3.6) / 3.6;  // integer km/h
        speed_poll = -1.0;
      }
      if (round_start + rpm_poll <= t && rpm_poll >= 0.0) {
        const TruthSample s = truth_at(drive, round_start + rpm_poll);
        freq = band_limited(std::round(s.freq * 60.0) / 60.0, s.freq, o);  // integer rpm
        rpm_poll = -1.0;
      }
      if (speed_poll < 0.0 && rpm_poll < 0.0) {
        round_start += o.obd_refresh * (0.9 + 0.2 * unit(rng));
        speed_poll = o.obd_skew * unit(rng);
        rpm_poll = o.obd_skew * unit(rng);
      } else {
        break;
      }
    }
    Observation ob;
    ob.truth = truth_at(drive, t);
    ob.speed = speed;
    ob.freq = freq;
    out.push_back(ob);
  }
  return out;
}

}  // namespace

std::vector<Observation> observe(const Drive& drive, const ObservationOptions& options) {
  if (!(options.period > 0.0) || !(options.sigma_speed >= 0.0) || !(options.sigma_freq >= 0.0) ||
      !(options.obd_refresh > 0.0) || !(options.obd_skew >= 0.0)) {
    throw std::invalid_argument("observe: period and refresh must be > 0, noise and skew >= 0");
  }
  std::mt19937_64 rng(options.seed);
  return options.obd ? observe_obd(drive, options, rng) : observe_gps(drive, options, rng);
}

std::vector<Sample> to_samples(const std::vector<Observation>& observations) {
  std::vector<Sample> out;
  out.reserve(observations.size());
  for (const Observation& o : observations)
    out.push_back({o.truth.t, o.speed, o.freq});
  return out;
}

std::vector<Observation> simulate_observations(const Vehicle& vehicle, DrivingStyle style, double duration,
                                               int drives, std::uint64_t seed,
                                               const ObservationOptions& observation) {
  std::vector<Observation> all;
  double offset = 0.0;
  for (int d = 0; d < drives; ++d) {
    DriveOptions opt;
    opt.style = style;
    opt.duration = duration;
    opt.dt = std::min(1.0, observation.period);
    opt.seed = seed + 1000003ULL * static_cast<std::uint64_t>(d);
    const Drive drive = simulate_drive(vehicle, opt);
    ObservationOptions obs = observation;
    obs.seed = observation.seed ^ (seed * 0x9E3779B97F4A7C15ULL + static_cast<std::uint64_t>(d));
    std::vector<Observation> part = observe(drive, obs);
    for (Observation& o : part) {
      o.truth.t += offset;
      all.push_back(o);
    }
    offset += duration + 60.0;
  }
  return all;
}

}  // namespace gearpulse::sim
