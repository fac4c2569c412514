// First-drive bench of the cold start: from an empty state, a first 30-minute simulated drive with a 60 s
// GPS outage every 3 minutes (outage_protocol.hpp: the first 120 s in), replayed as the daemon runs it:
// the training pairs so far (1 Hz, none in an outage), the learning schedule looked at every 5 s of drive
// time (daemon/learning_schedule.hpp), at its times a fit with the daemon's fitter, the gears the refit
// lacks kept and a one-gear model withdrawn by the daemon's rules, and the interval rule (retrain_interval,
// min_new_samples); the synthesis takes each new model between two steps. Beside it, the same drive with a
// model fitted beforehand on another 40-minute drive of the same car. Fits are taken to be instant (a fit on
// minutes of pairs takes milliseconds).
//
// Vehicles are drawn by sim::random_vehicle(seed) (4-7 gears, nothing tuned to the presets), mixed
// driving, the engine cold at the start; observed as the daemon sees them: the frequency at every 0.1 s
// tracker hop, a 1 Hz GPS fix given at each hop until the next (flagged new once).
// Per outage: distance error |integral of the output - integral of the true speed| over the 60 s, in m.
// Targets: a model within 3 minutes of moving; from minute 5, per-outage distance error within 2x the
// pre-trained one.
// Usage: bench_first_drive [--tuning | --report | --seeds A B] [--wide] [--verbose] [--trace MINUTE]
//        [--synth KEY=VALUE[,...]] [--require NAME<=VALUE]...
//   --require (bench/requirements.hpp) holds the figures first_model_worst_min (min of moving),
//   cold_over_pretrained_from_min5 and known_gears_cold_over_pretrained_from_min5 (ratios), cold_m_from_min5
//   and known_gears_cold_m_from_min5 (m per outage) to thresholds.
//   --tuning: seeds 1-10 (the seeds the schedule's defaults were chosen on); --report (default): 101-120.
//   --wide: the vehicles drawn by sim::wide_vehicle(seed) (3-9 gears, diesels, motorcycles, irregular
//   ladders) instead, a robustness check.
//   --synth sets SynthTuning fields of both runs' synthesis (bench/synth_settings.hpp), e.g. a rule off.
//   --verbose adds each fit's ladder, each outage, for an outage in gears the model lacks the seconds in
//   them below, inside and above its ladder, and the outages in a gear not learned yet split by where.
//   --trace MINUTE steps through the cold start's outage that begins at MINUTE (every outage when negative)
//   every 0.5 s from 10 s before it: true gear, clutch and speed, revs, fix, output, the most probable
//   ladder position with its belief, the ladder's thetas.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "bench/outage_protocol.hpp"
#include "bench/requirements.hpp"
#include "bench/synth_settings.hpp"
#include "core/estimator.hpp"
#include "core/speed_synth.hpp"
#include "daemon/fitter.hpp"
#include "daemon/learning_schedule.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::GearModel;
using gearpulse::Sample;
namespace sim = gearpulse::sim;
namespace gd = gearpulse::daemon;
using namespace gearpulse::bench;

namespace {

constexpr double kDriveLength = 1800.0;      // s
constexpr double kPretrainLength = 2400.0;   // s, as the demo's training drive
constexpr double kLookEvery = 5.0;           // s: the retrainer's look at the schedule while young
constexpr double kRetrainInterval = 600.0;   // s, [model] retrain_interval's default
constexpr std::size_t kMinNewSamples = 600;  // [model] min_new_samples' default
constexpr double kColdStart = 0.5;           // the engine's idle 50 % high at the start

struct Outage {
  double start = 0.0;     // s into the drive
  double truth = 0.0;     // m driven
  double error = 0.0;     // m, |output - truth| of the distance
  std::size_t gears = 0;  // gears of the model in use when the outage began
  double moving = 0.0;    // s of moving in the pairs when it began
  double unseen = 0.0;    // share of its time with the clutch transmitting (engaged or slipping) spent in a
                          // gear the model lacks (no theta within a factor of 1.06)
  double engaged = 0.0;   // s with the clutch transmitting
  // s with the clutch transmitting in a gear the model lacks, by where that gear lies against the model's
  // ladder: below its lowest gear, between two of its gears, above its top gear.
  double below = 0.0, inside = 0.0, above = 0.0;
  int lacked_low = 0, lacked_high = 0;  // lowest and highest true gear so driven (0: none)
};

struct Run {
  std::vector<Outage> outages;
  double first_model_drive = -1.0;   // s into the drive the first model came, -1 = never
  double first_model_moving = -1.0;  // s of moving then
  std::size_t fits = 0;
  std::size_t final_gears = 0;
};

// --trace: the outage that begins at `minute` (every outage when negative) stepped through, every 0.5 s from
// 10 s before it, for the cold start.
struct Trace {
  bool on = false;
  double minute = -1.0;
};

// One line of the trace: the truth, the readings, the output and the belief after a step.
void trace_step(const gearpulse::SpeedSynthesizer& synth, const sim::Observation& r, double fix,
                const gearpulse::SynthOutput& o) {
  const int n = synth.ladder_gears();
  int best = 0;
  for (int j = 1; j <= n + 1; ++j)
    if (synth.position_probability(j) > synth.position_probability(best)) best = j;
  std::printf(
      "    t %7.1f  true gear %d clutch %d v %5.2f | freq %6.1f gps %5.2f | out %5.2f gear %d | map %2d "
      "(%.2f)",
      r.truth.t, r.truth.gear, static_cast<int>(r.truth.clutch), r.truth.speed, r.freq, fix, o.speed, o.gear,
      best, synth.position_probability(best));
  std::printf(" | ladder");
  for (int j = 1; j <= n; ++j)
    std::printf(" %.4f", synth.ladder_theta(j));
  std::printf("\n");
}

// The drive stepped through the synthesis; with `pretrained` null the daemon's cold start learns as it goes.
Run drive(const sim::Drive& d, const std::shared_ptr<const GearModel>& pretrained,
          const gearpulse::SynthTuning& tuning, bool verbose, Trace trace = {}) {
  sim::ObservationOptions hop;
  hop.period = 0.1;
  hop.seed = d.options.seed + 7;
  const std::vector<sim::Observation> rows = sim::observe(d, hop);
  gearpulse::SpeedSynthesizer synth(pretrained, tuning);
  const auto fitter = gd::make_estimator_fitter();
  gd::LearningSchedule schedule;  // the daemon's defaults
  std::shared_ptr<const GearModel> model = pretrained;
  std::vector<Sample> pairs;
  std::size_t new_pairs = 0;
  double next_look = 0.0, next_interval = kRetrainInterval;
  Run run;
  long fix_index = -1;
  double fix = gearpulse::kMissing;
  std::optional<Outage> current;
  double prev_t = 0.0, prev_out = 0.0, prev_true = 0.0;
  const auto refit = [&](const gd::PairsSummary& summary) {
    GearModel fitted = fitter(pairs, {});
    ++run.fits;
    new_pairs = 0;
    if (fitted.empty() && model && gd::one_gear_withdrawn(*model, pairs)) {
      model = nullptr;
      synth.set_model(nullptr);
    }
    if (fitted.empty()) {
      if (verbose)
        std::printf("  no ladder at %.0f s (%zu pairs, moving %.0f s; model in use: %zu gears): %s\n",
                    pairs.back().t, pairs.size(), summary.moving_time, model ? model->gears.size() : 0,
                    fitted.reason.c_str());
      return;
    }
    if (model)
      fitted = gd::keep_seen_gears(*model, std::move(fitted), pairs, schedule.settings().cluster_pairs);
    if (!model && run.first_model_drive < 0.0) {
      run.first_model_drive = pairs.back().t;
      run.first_model_moving = summary.moving_time;
    }
    model = std::make_shared<const GearModel>(std::move(fitted));
    synth.set_model(model);
    if (verbose) {
      std::printf("  fit at %.0f s (%zu pairs, moving %.0f s):", pairs.back().t, pairs.size(),
                  summary.moving_time);
      for (const auto& g : model->gears)
        std::printf(" %.4f", g.theta);
      std::printf(" | true:");
      for (double th : d.vehicle.theta)
        std::printf(" %.4f", th);
      std::vector<double> seen(d.vehicle.theta.size() + 1, 0.0);  // s engaged in each gear, GPS present
      for (const auto& tr : d.truth)
        if (tr.t <= pairs.back().t && tr.clutch == sim::Clutch::kEngaged && !in_outage(tr.t))
          seen[static_cast<std::size_t>(tr.gear)] += d.options.dt;
      std::printf(" | s in each gear so far:");
      for (std::size_t g = 1; g < seen.size(); ++g)
        std::printf(" %.0f", seen[g]);
      std::printf("\n");
    }
  };
  for (const sim::Observation& r : rows) {
    const double t = r.truth.t;
    const bool out = in_outage(t);
    const long index = std::lround(std::floor(t + 1e-6));
    const bool fresh = !out && index != fix_index;
    if (fresh) {
      fix = r.speed;
      fix_index = index;
      if (!pretrained && std::isfinite(r.freq)) {
        pairs.push_back({t, r.speed, r.freq});
        ++new_pairs;
      }
    }
    const gearpulse::SynthOutput o = synth.step(t, out ? gearpulse::kMissing : fix, r.freq, fresh);
    if (trace.on && std::lround(t * 10.0) % 5 == 0) {
      const double start =
          kOutageStart + kOutagePeriod * std::floor((t + 10.0 - kOutageStart) / kOutagePeriod);
      if (start >= kOutageStart && t >= start - 10.0 && t < start + kOutageLength &&
          (trace.minute < 0.0 || std::abs(start / 60.0 - trace.minute) < 0.01))
        trace_step(synth, r, out ? gearpulse::kMissing : fix, o);
    }
    if (out && current && r.truth.gear > 0) {
      const double theta = d.vehicle.theta[static_cast<std::size_t>(r.truth.gear - 1)];
      const bool known = model && std::any_of(model->gears.begin(), model->gears.end(), [&](const auto& g) {
                           return std::abs(std::log(g.theta / theta)) < std::log(1.06);
                         });
      current->engaged += hop.period;
      current->unseen += known ? 0.0 : hop.period;
      if (!known) {
        double lo = std::numeric_limits<double>::infinity(), hi = 0.0;
        if (model)
          for (const auto& g : model->gears)
            lo = std::min(lo, g.theta), hi = std::max(hi, g.theta);
        (theta < lo ? current->below : theta > hi ? current->above : current->inside) += hop.period;
        const int gear = r.truth.gear;
        current->lacked_low = current->lacked_low == 0 ? gear : std::min(current->lacked_low, gear);
        current->lacked_high = std::max(current->lacked_high, gear);
      }
    }
    if (out) {
      if (!current) {
        current =
            Outage{t, 0.0, 0.0, model ? model->gears.size() : 0, gd::summarize_pairs(pairs).moving_time};
        prev_t = t, prev_out = o.speed, prev_true = r.truth.speed;
      } else {
        const double dt = t - prev_t;
        current->truth += 0.5 * dt * (r.truth.speed + prev_true);
        current->error += 0.5 * dt * (o.speed + prev_out);
        prev_t = t, prev_out = o.speed, prev_true = r.truth.speed;
      }
    } else if (current) {
      current->error = std::abs(current->error - current->truth);
      current->unseen = current->engaged > 0.0 ? current->unseen / current->engaged : 0.0;
      run.outages.push_back(*current);
      current.reset();
    }
    if (pretrained || pairs.empty()) continue;
    // The retrainer: the schedule while young, the interval rule always.
    bool due = false;
    if (t >= next_interval) {
      next_interval += kRetrainInterval;
      due = new_pairs >= kMinNewSamples;
    }
    if (t >= next_look) {
      next_look += kLookEvery;
      const gd::PairsSummary summary = gd::summarize_pairs(pairs, model.get());
      if (schedule.young(summary, model != nullptr) && schedule.due(summary, model != nullptr)) {
        schedule.tried(summary);
        refit(summary);
        continue;
      }
    }
    if (due) refit(gd::summarize_pairs(pairs, model.get()));
  }
  if (current) {
    current->error = std::abs(current->error - current->truth);
    current->unseen = current->engaged > 0.0 ? current->unseen / current->engaged : 0.0;
    run.outages.push_back(*current);
  }
  run.final_gears = model ? model->gears.size() : 0;
  return run;
}

double mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v)
    s += x;
  return v.empty() ? std::nan("") : s / static_cast<double>(v.size());
}

}  // namespace

int main(int argc, char** argv) {
  std::uint64_t first = 101, last = 120;
  const char* which = "report";
  bool verbose = false, wide = false;
  Trace trace;
  gearpulse::SynthTuning tuning;  // the daemon's defaults unless --synth KEY=VALUE sets a field
  gearpulse::bench::Requirements required;
  if (!required.parse(argc, argv)) return 2;
  for (int i = 1; i < argc; ++i) {
    const std::string_view a = argv[i];
    if (a == "--wide") {
      wide = true;
    } else if (a == "--tuning") {
      first = 1, last = 10, which = "tuning";
    } else if (a == "--report") {
      first = 101, last = 120, which = "report";
    } else if (a == "--seeds" && i + 2 < argc) {
      first = std::strtoull(argv[i + 1], nullptr, 10);
      last = std::strtoull(argv[i + 2], nullptr, 10);
      which = "chosen";
      i += 2;
    } else if (a == "--verbose") {
      verbose = true;
    } else if (a == "--trace" && i + 1 < argc) {
      trace = {true, std::strtod(argv[++i], nullptr)};
    } else if (a == "--synth" && i + 1 < argc && gearpulse::bench::apply_settings(tuning, argv[i + 1])) {
      ++i;
    } else {
      std::fprintf(stderr,
                   "usage: bench_first_drive [--tuning | --report | --seeds A B] [--wide] [--verbose] "
                   "[--trace MINUTE] "
                   "[--synth KEY=VALUE] [--require NAME<=VALUE]...\n");
      return 2;
    }
  }
  std::printf(
      "first drive from an empty state: seeds %llu-%llu (%s set), sim::%s(seed), mixed, "
      "%.0f min, 60 s outage every 3 min from minute 2\n",
      static_cast<unsigned long long>(first), static_cast<unsigned long long>(last), which,
      wide ? "wide_vehicle" : "random_vehicle", kDriveLength / 60.0);
  std::vector<std::vector<double>> cold_err, pre_err, truth_m;  // per outage index, over seeds
  std::vector<double> first_moving, first_drive;
  std::size_t never = 0, late = 0;
  double cold_after5 = 0.0, pre_after5 = 0.0;
  std::size_t outages_after5 = 0, within_2x = 0;
  // Outages from minute 5 split by whether the car spent kUnseenShare or more of their time in gear (the
  // clutch engaged or slipping) in a gear the cold-start model had not learned when they began.
  constexpr double kUnseenShare = 0.1;
  double known_cold = 0.0, known_pre = 0.0, unseen_cold = 0.0, unseen_pre = 0.0;
  std::size_t known_n = 0, unseen_n = 0, known_within = 0;
  // The outages in a gear not learned yet by where its gears mostly lie: below, inside, above the ladder.
  std::array<double, 3> lacked_cold{}, lacked_pre{};
  std::array<std::size_t, 3> lacked_n{};
  for (std::uint64_t seed = first; seed <= last; ++seed) {
    const sim::Vehicle car = wide ? sim::wide_vehicle(seed) : sim::random_vehicle(seed);
    sim::DriveOptions options;
    options.style = sim::DrivingStyle::kMixed;
    options.duration = kDriveLength;
    options.dt = 0.1;
    options.seed = seed;
    options.cold_start = kColdStart;
    const sim::Drive first_drive_sim = sim::simulate_drive(car, options);
    // The model fitted beforehand: another drive of the same car, its 1 Hz pairs.
    sim::DriveOptions other = options;
    other.duration = kPretrainLength;
    other.dt = 1.0;
    other.seed = seed + 100000;
    sim::ObservationOptions gps1;
    gps1.seed = seed + 200000;
    const auto pre_pairs = sim::to_samples(sim::observe(sim::simulate_drive(car, other), gps1));
    const auto pre_model = std::make_shared<const GearModel>(gd::make_estimator_fitter()(pre_pairs, {}));
    const Run cold = drive(first_drive_sim, nullptr, tuning, verbose, trace);
    const Run pre = drive(first_drive_sim, pre_model->empty() ? nullptr : pre_model, tuning, false);
    if (cold.first_model_drive < 0.0) {
      ++never;
    } else {
      first_moving.push_back(cold.first_model_moving / 60.0);
      first_drive.push_back(cold.first_model_drive / 60.0);
      late += cold.first_model_moving > 180.0 ? 1 : 0;
    }
    std::printf(
        "seed %3llu %-10s %d gears: first model at %5.2f min driven (%5.2f min moving), %zu fits, "
        "final %zu gears; pre-trained %zu gears\n",
        static_cast<unsigned long long>(seed), car.name.c_str(), car.gears(), cold.first_model_drive / 60.0,
        cold.first_model_moving / 60.0, cold.fits, cold.final_gears, pre_model->gears.size());
    for (std::size_t k = 0; k < cold.outages.size() && k < pre.outages.size(); ++k) {
      if (cold_err.size() <= k) cold_err.resize(k + 1), pre_err.resize(k + 1), truth_m.resize(k + 1);
      cold_err[k].push_back(cold.outages[k].error);
      pre_err[k].push_back(pre.outages[k].error);
      truth_m[k].push_back(cold.outages[k].truth);
      if (cold.outages[k].start >= 300.0) {
        cold_after5 += cold.outages[k].error;
        pre_after5 += pre.outages[k].error;
        ++outages_after5;
        within_2x += cold.outages[k].error <= 2.0 * pre.outages[k].error + 1.0 ? 1 : 0;  // 1 m: rounding
        const bool known = cold.outages[k].unseen < kUnseenShare;
        (known ? known_cold : unseen_cold) += cold.outages[k].error;
        (known ? known_pre : unseen_pre) += pre.outages[k].error;
        ++(known ? known_n : unseen_n);
        known_within += known && cold.outages[k].error <= 2.0 * pre.outages[k].error + 1.0 ? 1 : 0;
        if (!known) {  // by where the gears it lacks mostly lie
          const Outage& o = cold.outages[k];
          const std::size_t where = o.below >= o.inside && o.below >= o.above ? 0
                                    : o.inside >= o.above                     ? 1
                                                                              : 2;
          lacked_cold[where] += o.error;
          lacked_pre[where] += pre.outages[k].error;
          ++lacked_n[where];
        }
      }
      if (verbose)
        std::printf(
            "    outage at %4.1f min: %4.0f m driven; cold %zu gears %6.1f m (%3.0f%% in a gear it lacks), "
            "pre-trained %6.1f m\n",
            cold.outages[k].start / 60.0, cold.outages[k].truth, cold.outages[k].gears, cold.outages[k].error,
            100.0 * cold.outages[k].unseen, pre.outages[k].error);
      if (verbose && cold.outages[k].unseen > 0.0)
        std::printf(
            "      in gears it lacks (true %d-%d): %.0f s below its ladder, %.0f s inside, %.0f s above\n",
            cold.outages[k].lacked_low, cold.outages[k].lacked_high, cold.outages[k].below,
            cold.outages[k].inside, cold.outages[k].above);
    }
  }
  std::printf("\nper outage, mean over seeds (distance error in m, and in %% of the distance driven):\n");
  std::printf("%8s %10s | %16s | %16s | %6s\n", "minute", "driven m", "cold start", "pre-trained", "ratio");
  for (std::size_t k = 0; k < cold_err.size(); ++k) {
    const double c = mean(cold_err[k]), p = mean(pre_err[k]), m = mean(truth_m[k]);
    std::printf("%8.0f %10.0f | %7.1f (%5.1f%%) | %7.1f (%5.1f%%) | %6.2f\n",
                (kOutageStart + k * kOutagePeriod) / 60.0, m, c, 100.0 * c / m, p, 100.0 * p / m, c / p);
  }
  std::sort(first_moving.begin(), first_moving.end());
  std::printf(
      "\nfirst model: median %.2f min moving (%.2f driven), worst %.2f min moving; later than 3 min "
      "of moving: %zu, never: %zu of %llu drives\n",
      quantile(first_moving, 0.5), quantile(first_drive, 0.5),
      first_moving.empty() ? std::nan("") : first_moving.back(), late, never,
      static_cast<unsigned long long>(last - first + 1));
  std::printf(
      "from minute 5: cold-start distance error %.1f m per outage against %.1f m pre-trained (ratio %.2f); "
      "%zu of %zu outages within 2x the pre-trained (+1 m)\n",
      cold_after5 / static_cast<double>(outages_after5), pre_after5 / static_cast<double>(outages_after5),
      cold_after5 / pre_after5, within_2x, outages_after5);
  std::printf(
      "  in gears the model knew (under %.0f%% of the time in gear in others, slipping included): %zu "
      "outages, %.1f m against "
      "%.1f m (ratio %.2f), %zu of %zu within 2x (+1 m)\n",
      100.0 * kUnseenShare, known_n, known_cold / static_cast<double>(known_n),
      known_pre / static_cast<double>(known_n), known_cold / known_pre, known_within, known_n);
  std::printf("  in a gear the model had not learned yet: %zu outages, %.1f m against %.1f m\n", unseen_n,
              unseen_cold / static_cast<double>(unseen_n), unseen_pre / static_cast<double>(unseen_n));
  if (verbose)
    for (std::size_t w = 0; w < 3; ++w)
      if (lacked_n[w] > 0)
        std::printf("    mostly %s the model's ladder: %zu outages, %.1f m against %.1f m\n",
                    w == 0   ? "below"
                    : w == 1 ? "inside"
                             : "above",
                    lacked_n[w], lacked_cold[w] / static_cast<double>(lacked_n[w]),
                    lacked_pre[w] / static_cast<double>(lacked_n[w]));
  required.report("first_model_worst_min", never > 0 || first_moving.empty()
                                               ? std::numeric_limits<double>::infinity()
                                               : first_moving.back());
  required.report("cold_over_pretrained_from_min5", cold_after5 / pre_after5);
  required.report("known_gears_cold_over_pretrained_from_min5", known_cold / known_pre);
  required.report("cold_m_from_min5", cold_after5 / static_cast<double>(outages_after5));
  required.report("known_gears_cold_m_from_min5", known_cold / static_cast<double>(known_n));
  return required.exit_status();
}
