// Simulated-drive bench of the outage speed synthesis, the counterpart of bench_real_logs with a known truth:
// per vehicle, fit the gear model on one drive, replay drives of other seeds and styles with GPS outages
// blanked out of the speed column, and measure the output inside the outages against the TRUE speed at
// the row time (not the observed one, which an OBD logger rounds and delays).
//
// Outages as bench_real_logs: 60 s long, the first 120 s after the drive starts, then one every 180 s.
// Methods compared:
//   (a) hold the last GPS speed;
//   (c) the gear chosen with hindsight (theta x freq closest to the true speed, or standing), fitted
//       model: a floor;
//   (d) gearpulse's SpeedSynthesizer with the fitted model, causal, stepped at every observed row (the
//       daemon steps it at every 0.1 s tracker hop, as the live kind below; the others show what the
//       filter itself does at each rate).
// Each drive is observed four ways: an OBD logger (integer km/h and rpm, a 1.8 s polling round, skewed
// polls, rows every 0.5 s as the Etios logs), GPS at 1 Hz and GPS at 10 Hz, and as the daemon runs: the
// frequency at every 0.1 s tracker hop with a 1 Hz GPS fix given at each hop until the next (the newest
// fresh fix, flagged new once), its model fitted on the 1 Hz pairs the daemon trains on. The same drives
// are used for all, so a synthesis that does not depend on the sample rate gives about the same 1 Hz and
// 10 Hz figures. "gear off" is the share of outage samples with the clutch engaged in which the synthesizer's
// gear (mapped to the true gear of nearest theta) differs from the true gear or is none.
// Usage: bench_synth_sim [SEED] [--quick] [--random N] [--trace FILE]   (--random N: N vehicles drawn by
// sim::random_vehicle instead of the presets, one round each, so that nothing here is tuned to the
// presets; --trace: every outage row as CSV, with the true gear and clutch state beside the synthesis;
// the synthesizer's gear is mapped to the true gear)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "bench/outage_protocol.hpp"
#include "core/estimator.hpp"
#include "core/speed_synth.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::GearModel;
namespace sim = gearpulse::sim;

using namespace gearpulse::bench;  // the shared outage protocol

namespace {

struct ObservationKind {
  const char* name;
  sim::ObservationOptions options;  // the rows replayed
  sim::ObservationOptions fit;      // the rows the model is fitted on
  double fix_interval = 0.0;        // s: GPS fixes this far apart, held at the rows between (0 = every row)
};

std::vector<ObservationKind> observation_kinds() {
  sim::ObservationOptions obd;
  obd.obd = true;
  obd.period = 0.5;  // rows as the Etios logger writes them; values refresh once per polling round
  obd.obd_refresh = 1.8;
  obd.obd_skew = 1.0;
  sim::ObservationOptions gps1;  // defaults: 1 Hz, sigma_v 0.05 m/s, sigma_s 0.2 Hz
  sim::ObservationOptions gps10 = gps1;
  gps10.period = 0.1;
  return {{"OBD 1.8 s", obd, obd},
          {"GPS 1 Hz", gps1, gps1},
          {"GPS 10 Hz", gps10, gps10},
          {"live", gps10, gps1, 1.0}};
}

struct ReplayDrive {
  sim::DrivingStyle style;
  double duration;  // s
};

struct Errors {
  std::vector<double> a, c, d;
  std::size_t gear_samples = 0;  // outage samples with a true gear and the clutch engaged
  std::size_t gear_off = 0;      // of those, the synthesizer's gear differs

  void append(const Errors& o) {
    a.insert(a.end(), o.a.begin(), o.a.end());
    c.insert(c.end(), o.c.begin(), o.c.end());
    d.insert(d.end(), o.d.begin(), o.d.end());
    gear_samples += o.gear_samples;
    gear_off += o.gear_off;
  }
};

std::FILE* g_trace = nullptr;  // --trace FILE
const char* g_label = "";      // vehicle/observation/style of the drive being replayed

// The vehicle's gear (1..M) whose true theta is nearest each model gear's, index 0 = no gear: a fit with
// a spurious or a missing gear still has its other gears compared with the right true gears.
std::vector<int> true_gears_of(const sim::Vehicle& car, const GearModel& model) {
  std::vector<int> map(model.gears.size() + 1, 0);
  for (std::size_t i = 0; i < model.gears.size(); ++i) {
    double best = 0.0;
    for (std::size_t g = 0; g < car.theta.size(); ++g) {
      const double d = std::abs(std::log(model.gears[i].theta / car.theta[g]));
      if (map[i + 1] == 0 || d < best) map[i + 1] = static_cast<int>(g) + 1, best = d;
    }
  }
  return map;
}

// Replays one observed drive with outages; appends |error| in km/h of every row inside an outage. With a
// fix interval, a row's speed is the fix taken at the last whole interval, given at every row as the
// daemon gives the newest fresh fix at every hop, flagged new at the first.
void replay(const std::vector<sim::Observation>& rows, const GearModel& model,
            const std::vector<int>& true_gear, double fix_interval, Errors& err) {
  if (rows.empty()) return;
  gearpulse::SpeedSynthesizer synth(std::make_shared<const GearModel>(model));
  const double t0 = rows.front().truth.t;
  double last_gps = 0.0, hold_c = 0.0;
  bool was_out = false;
  double last_speed = -1.0, last_freq = -1.0;
  double fix = gearpulse::kMissing;
  long fix_index = -1;
  gearpulse::LogReplayer replayer(synth);
  for (const sim::Observation& r : rows) {
    // As gearpulse's readers do with OBD logs: a row repeating both held values carries nothing new.
    if (r.speed == last_speed && r.freq == last_freq) continue;
    last_speed = r.speed;
    last_freq = r.freq;
    const double t = r.truth.t;
    const bool out = in_outage(t - t0);
    gearpulse::SynthOutput o;
    if (fix_interval > 0.0) {
      const long index = std::lround(std::floor((t - t0) / fix_interval + 1e-6));
      const bool fresh = !out && index != fix_index;
      if (fresh) {
        fix = r.speed;
        fix_index = index;
      }
      o = synth.step(t, out ? gearpulse::kMissing : fix, r.freq, fresh);
    } else {
      // As `gearpulse replay` does: a row whose speed the outage took and whose rpm is held brings nothing.
      o = replayer.step({t, out ? gearpulse::kMissing : r.speed, r.freq});
    }
    if (!out) {
      const double seen = fix_interval > 0.0 ? fix : r.speed;
      if (std::isfinite(seen)) last_gps = seen;
      was_out = false;
      continue;
    }
    if (!was_out) hold_c = last_gps;
    was_out = true;
    const double truth = r.truth.speed;
    if (std::isfinite(r.freq) && !model.gears.empty()) hold_c = hindsight_speed(model, truth, r.freq);
    if (std::FILE* tr = g_trace) {
      const int sg = o.gear > 0 && static_cast<std::size_t>(o.gear) < true_gear.size()
                         ? true_gear[static_cast<std::size_t>(o.gear)]
                         : 0;
      std::fprintf(tr, "%s,%.1f,%.2f,%d,%d,%.2f,%.2f,%d,%.2f\n", g_label, t, truth * kMsToKmh, r.truth.gear,
                   static_cast<int>(r.truth.clutch), r.freq, o.speed * kMsToKmh, sg, hold_c * kMsToKmh);
    }
    err.a.push_back(std::abs(last_gps - truth) * kMsToKmh);
    err.c.push_back(std::abs(hold_c - truth) * kMsToKmh);
    err.d.push_back(std::abs(o.speed - truth) * kMsToKmh);
    if (r.truth.gear > 0 && r.truth.clutch == sim::Clutch::kEngaged) {
      ++err.gear_samples;
      const bool known = o.gear > 0 && static_cast<std::size_t>(o.gear) < true_gear.size();
      if (!known || true_gear[static_cast<std::size_t>(o.gear)] != r.truth.gear) ++err.gear_off;
    }
  }
}

// Largest relative theta error in %, or a negative number when the gear count is wrong.
double max_theta_error(const sim::Vehicle& car, const GearModel& model) {
  if (model.gears.size() != car.theta.size()) return -1.0;
  double worst = 0.0;
  for (std::size_t i = 0; i < car.theta.size(); ++i)
    worst = std::max(worst, 100.0 * std::abs(model.gears[i].theta / car.theta[i] - 1.0));
  return worst;
}

void print_header() {
  std::printf("%-13s %-10s %9s %7s %8s | %-15s | %-15s | %-15s | %8s\n", "vehicle", "observed", "gears",
              "theta%", "samples", "(a) hold GPS", "(c) hindsight", "(d) synthesis", "gear off");
}

void print_line(const char* vehicle, const char* kind, const std::string& gears, const std::string& theta,
                const Errors& e) {
  const double off = e.gear_samples > 0
                         ? 100.0 * static_cast<double>(e.gear_off) / static_cast<double>(e.gear_samples)
                         : 0.0;
  std::printf("%-13s %-10s %9s %7s %8zu | %6.2f / %6.2f | %6.2f / %6.2f | %6.2f / %6.2f | %7.1f%%\n", vehicle,
              kind, gears.c_str(), theta.c_str(), e.d.size(), quantile(e.a, 0.5), quantile(e.a, 0.95),
              quantile(e.c, 0.5), quantile(e.c, 0.95), quantile(e.d, 0.5), quantile(e.d, 0.95), off);
}

}  // namespace

// A cold engine's idle at the start, above the warm idle (sim::DriveOptions::cold_start): the fit drive and
// every other replay drive start cold.
constexpr double kColdStart = 0.5;
constexpr bool starts_cold(std::size_t replay) {
  return replay % 2 == 0;
}

int main(int argc, char** argv) {
  std::uint64_t seed = 1;
  bool quick = false;
  int random = 0;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> trace(nullptr, &std::fclose);
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--quick") {
      quick = true;
    } else if (arg == "--random" && i + 1 < argc) {
      random = std::atoi(argv[++i]);
      if (random < 1) {
        std::fprintf(stderr, "bench_synth_sim: --random needs a count >= 1\n");
        return 2;
      }
    } else if (arg == "--trace" && i + 1 < argc) {
      trace.reset(std::fopen(argv[++i], "w"));
      if (!trace) {
        std::fprintf(stderr, "bench_synth_sim: cannot write %s\n", argv[i]);
        return 1;
      }
      g_trace = trace.get();
      std::fprintf(g_trace, "run,t,speed_kmh,gear,clutch,freq_hz,synth_kmh,synth_gear,hindsight_kmh\n");
    } else {
      char* end = nullptr;
      const unsigned long long v = std::strtoull(argv[i], &end, 10);
      if (argv[i][0] == '-' || end == argv[i] || *end != '\0') {
        std::fprintf(stderr, "usage: bench_synth_sim [SEED] [--quick] [--random N] [--trace FILE]\n");
        return 2;
      }
      seed = v;
    }
  }
  const auto start = std::chrono::steady_clock::now();

  std::vector<sim::Vehicle> vehicles;
  if (random > 0) {
    for (int i = 0; i < random; ++i)
      vehicles.push_back(sim::random_vehicle(seed * 1000 + static_cast<std::uint64_t>(i)));
  } else {
    for (const char* name : quick ? std::vector<const char*>{"hatch-5", "close-6", "bmw-520i"}
                                  : std::vector<const char*>{"hatch-5", "close-6", "wide-4", "van-6",
                                                             "sport-7", "compact-4", "bmw-520i"})
      vehicles.push_back(sim::vehicle_preset(name));
  }
  const double train_duration = quick ? 1200.0 : 2400.0;
  const int rounds = quick || random > 0 ? 1 : 5;
  const std::vector<ReplayDrive> replays =
      quick
          ? std::vector<ReplayDrive>{{sim::DrivingStyle::kUrban, 900.0}, {sim::DrivingStyle::kHighway, 900.0}}
          : std::vector<ReplayDrive>{{sim::DrivingStyle::kUrban, 1800.0},
                                     {sim::DrivingStyle::kMixed, 1800.0},
                                     {sim::DrivingStyle::kTrafficJam, 1200.0},
                                     {sim::DrivingStyle::kHighway, 2400.0}};
  const std::vector<ObservationKind> kinds = observation_kinds();

  std::printf("bench_synth_sim seed %llu%s: fit on %.0f min mixed (seed %llu), replay",
              static_cast<unsigned long long>(seed), quick ? " (quick)" : "", train_duration / 60.0,
              static_cast<unsigned long long>(seed));
  for (std::size_t i = 0; i < replays.size(); ++i)
    std::printf("%s %.0f min %s (seed %llu)", i ? "," : "", replays[i].duration / 60.0,
                std::string(sim::style_name(replays[i].style)).c_str(),
                static_cast<unsigned long long>(seed + 101 + i));
  std::printf(
      "\ncold engine (idle +%.0f %%, settling in %.0f s) at the start of the fit drive and of replays",
      100.0 * kColdStart, sim::DriveOptions{}.warm_up);
  for (std::size_t i = 0; i < replays.size(); ++i)
    if (starts_cold(i)) std::printf(" %zu", i + 1);
  std::printf("\noutages 60 s from 120 s, every 180 s; |error| against the true speed, km/h median / p95\n");
  std::printf(
      "%d round(s): round r adds 1000 r to every seed; vehicle (true gear count), gears found by each\n"
      "round's fit, theta%% = largest theta error among fits with the right count (- = none)\n\n",
      rounds);
  print_header();

  std::vector<Errors> overall(kinds.size());
  std::vector<std::vector<Errors>> by_style(kinds.size(), std::vector<Errors>(replays.size()));
  for (const sim::Vehicle& car : vehicles) {
    const std::string& name = car.name;
    std::vector<Errors> per_kind(kinds.size());
    std::vector<std::string> found(kinds.size());
    std::vector<double> worst_theta(kinds.size(), -1.0);
    for (int round = 0; round < rounds; ++round) {
      const std::uint64_t base = seed + 1000 * static_cast<std::uint64_t>(round);
      // Truth at 10 Hz serves every observation kind: a seed gives one drive whatever the output grid.
      sim::DriveOptions train_opt;
      train_opt.style = sim::DrivingStyle::kMixed;
      train_opt.duration = train_duration;
      train_opt.dt = 0.1;
      train_opt.seed = base;
      train_opt.cold_start = kColdStart;
      const sim::Drive train = sim::simulate_drive(car, train_opt);
      std::vector<sim::Drive> tests;
      for (std::size_t i = 0; i < replays.size(); ++i) {
        sim::DriveOptions opt;
        opt.style = replays[i].style;
        opt.duration = replays[i].duration;
        opt.dt = 0.1;
        opt.seed = base + 101 + i;
        opt.cold_start = starts_cold(i) ? kColdStart : 0.0;
        tests.push_back(sim::simulate_drive(car, opt));
      }
      for (std::size_t k = 0; k < kinds.size(); ++k) {
        sim::ObservationOptions obs = kinds[k].options;
        obs.seed = base * 7919 + 1;
        sim::ObservationOptions fit_obs = kinds[k].fit;
        fit_obs.seed = obs.seed;
        const GearModel model =
            gearpulse::fit_gear_model(sim::to_samples(sim::observe(train, fit_obs)), {}).model;
        const std::vector<int> true_gear = true_gears_of(car, model);
        for (std::size_t i = 0; i < tests.size(); ++i) {
          obs.seed = base * 7919 + 2 + i;
          Errors one;
          const std::string label =
              name + "/" + kinds[k].name + "/" + std::string(sim::style_name(replays[i].style));
          g_label = label.c_str();
          replay(sim::observe(tests[i], obs), model, true_gear, kinds[k].fix_interval, one);
          by_style[k][i].append(one);
          per_kind[k].append(one);
        }
        found[k] += (round ? "," : "") + std::to_string(model.gears.size());
        worst_theta[k] = std::max(worst_theta[k], max_theta_error(car, model));
      }
    }
    for (std::size_t k = 0; k < kinds.size(); ++k) {
      char theta[16] = "-";
      if (worst_theta[k] >= 0.0) std::snprintf(theta, sizeof theta, "%.2f", worst_theta[k]);
      const std::string vehicle = name + " (" + std::to_string(car.gears()) + ")";
      print_line(vehicle.c_str(), kinds[k].name, found[k], theta, per_kind[k]);
      overall[k].append(per_kind[k]);
    }
  }

  std::printf("\nby replay style, all vehicles\n");
  print_header();
  for (std::size_t i = 0; i < replays.size(); ++i)
    for (std::size_t k = 0; k < kinds.size(); ++k)
      print_line(std::string(sim::style_name(replays[i].style)).c_str(), kinds[k].name, "", "",
                 by_style[k][i]);

  std::printf("\noverall, all vehicles and drives (target for (d): median <= 1.5, p95 <= 8 km/h)\n");
  print_header();
  for (std::size_t k = 0; k < kinds.size(); ++k)
    print_line("all", kinds[k].name, "", "", overall[k]);

  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("\n(%.1f s)\n", secs);
  return 0;
}
