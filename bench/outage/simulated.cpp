// The outage bench's simulated workload: vehicles driven by the simulator, observed at each cadence with
// noise and latency, fitted on one drive and replayed on others.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "bench/outage/outage.hpp"
#include "core/estimator.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::bench::outage {

namespace {

struct Cadence {
  const char* name;
  const char* key;     // in the figures' names
  double freq_period;  // s between frequency readings (0 = OBD polling)
  double fix_period;   // s between GPS fixes
  double obd_refresh;  // s, OBD polling round (0 = not OBD)
};
constexpr Cadence kCadences[] = {
    {"daemon 10 Hz/1 Hz", "daemon", 0.1, 1.0, 0.0},
    {"1 Hz", "1hz", 1.0, 1.0, 0.0},
    {"OBD 2 s", "obd2s", 0.0, 0.0, 2.0},
    {"phone OBD 5 s", "obd5s", 0.0, 0.0, 5.0},
};
constexpr double kGpsLatency = 0.5;  // s
constexpr double kSigmaSpeed = 0.1;  // m/s
constexpr double kSigmaFreq = 0.3;   // Hz

double heavy(std::mt19937_64& rng) {
  std::student_t_distribution<double> t(3.0);
  return t(rng) / std::sqrt(3.0);  // unit variance
}

// GPS-like rows: the frequency every freq_period, a fix every fix_period given at every row until the next.
std::vector<Row> observe_gps(const sim::Drive& drive, const Cadence& c, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Row> rows;
  const double end = drive.truth.back().t;
  double fix = gearpulse::kMissing;
  long fix_index = -1;
  for (double t = kGpsLatency; t <= end; t += c.freq_period) {
    const sim::TruthSample now = sim::truth_at(drive, t);
    const long index = std::lround(std::floor(t / c.fix_period + 1e-6));
    bool fresh = false;
    if (index != fix_index) {
      fix = std::max(0.0, sim::truth_at(drive, t - kGpsLatency).speed + kSigmaSpeed * heavy(rng));
      fix_index = index;
      fresh = true;
    }
    const double f = now.freq + kSigmaFreq * heavy(rng);
    rows.push_back({t, fix, f > 0.0 ? f : gearpulse::kMissing, now.speed, fresh, now.gear});
  }
  return rows;
}

std::vector<Row> observe_obd(const sim::Drive& drive, const Cadence& c, std::uint64_t seed) {
  sim::ObservationOptions o;
  o.obd = true;
  o.period = 0.5;
  o.obd_refresh = c.obd_refresh;
  o.obd_skew = std::min(1.0, 0.5 * c.obd_refresh);
  o.seed = seed;
  std::vector<Row> rows;
  double last_speed = -1.0, last_freq = -1.0;
  for (const sim::Observation& x : sim::observe(drive, o)) {
    if (x.speed == last_speed && x.freq == last_freq) continue;  // a row repeating both held values
    last_speed = x.speed;
    last_freq = x.freq;
    rows.push_back({x.truth.t, x.speed, x.freq, x.truth.speed, true, x.truth.gear});
  }
  return rows;
}

std::vector<Row> observe(const sim::Drive& drive, const Cadence& c, std::uint64_t seed) {
  return c.obd_refresh > 0.0 ? observe_obd(drive, c, seed) : observe_gps(drive, c, seed);
}

sim::Drive drive_of(const sim::Vehicle& car, sim::DrivingStyle style, double duration, std::uint64_t seed) {
  sim::DriveOptions d;
  d.style = style;
  d.duration = duration;
  d.dt = 0.1;
  d.seed = seed;
  d.cold_start = 0.3;
  d.skip_downshift = 0.3;
  return sim::simulate_drive(car, d);
}

// The model the daemon would have: fitted on the 1 Hz pairs (or the OBD rows) of a mixed drive of
// `minutes` (40 unless --fit-minutes).
GearModel fit_model(const sim::Vehicle& car, const Cadence& c, double minutes, std::uint64_t seed) {
  const sim::Drive d = drive_of(car, sim::DrivingStyle::kMixed, 60.0 * minutes, seed);
  Cadence fit = c;
  if (fit.obd_refresh == 0.0) fit.freq_period = 1.0, fit.fix_period = 1.0;
  std::vector<Sample> samples;
  for (const Row& r : observe(d, fit, seed + 7))
    samples.push_back({r.t, r.gps, r.freq});
  return gearpulse::fit_gear_model(samples, {}).model;
}

}  // namespace

void simulated(bool report_set, int seeds, int randoms, const Options& opt, Workload& w) {
  const std::uint64_t base = report_set ? 1000 : 0;
  char title[200];
  std::snprintf(title, sizeof title,
                "Simulated vehicles, %s seeds %llu..%llu (fit on a %g-min mixed drive, replay 20 min of each "
                "style)",
                report_set ? "REPORT" : "TUNING", static_cast<unsigned long long>(base + 1),
                static_cast<unsigned long long>(base + static_cast<std::uint64_t>(seeds)), opt.fit_minutes);
  std::vector<sim::Vehicle> cars;
  for (const sim::Vehicle& v : sim::vehicle_presets())
    if (!v.is_cvt()) cars.push_back(v);
  for (int k = 1; k <= randoms; ++k)
    cars.push_back(sim::random_vehicle(base + 500 + static_cast<std::uint64_t>(k)));
  bool first = true;
  for (const Cadence& c : kCadences) {
    if (opt.cadence >= 0 && &c - kCadences != opt.cadence) continue;
    w.lines.push_back({first ? title : "", c.name, std::string("sim_") + c.key, true});
    first = false;
    for (const sim::Vehicle& car : cars)
      for (int s = 1; s <= seeds; ++s) {
        const std::uint64_t seed = base + static_cast<std::uint64_t>(s);
        const auto model =
            std::make_shared<const GearModel>(fit_model(car, c, opt.fit_minutes, seed * 31 + 3));
        if (opt.fits) {
          std::fprintf(stderr, "%s %s seed %llu fit", c.key, car.name.c_str(),
                       static_cast<unsigned long long>(seed));
          for (const auto& g : model->gears)
            std::fprintf(stderr, " %.4f", g.theta);
          std::fprintf(stderr, " | true");
          for (double th : car.theta)
            std::fprintf(stderr, " %.4f", th);
          std::fprintf(stderr, "\n");
        }
        if (model->gears.empty()) continue;
        int k = 0;
        for (const sim::DrivingStyle style : {sim::DrivingStyle::kMixed, sim::DrivingStyle::kUrban,
                                              sim::DrivingStyle::kTrafficJam, sim::DrivingStyle::kHighway}) {
          w.cases.push_back({w.lines.size() - 1, k, car.name,
                             observe(drive_of(car, style, 1200.0, seed * 31 + 11 + k), c, seed * 31 + 13 + k),
                             model, c.obd_refresh == 0.0, car.theta, static_cast<int>(seed)});
          ++k;
        }
      }
  }
}

}  // namespace gearpulse::bench::outage
