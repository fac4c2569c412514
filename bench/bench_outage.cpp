// Outage bench: how far the synthesized speed carries a navigator through GPS outages, per outage. The
// daemon's synthesis (SpeedSynthesizer) and the candidate IMM filter (ImmSpeedSynthesizer) run side by side
// against three baselines computed in the same run with the same model:
//   keep gear  - the gear engaged when GPS went (nearest theta), kept: theta x frequency;
//   hold speed - the last GPS speed;
//   hindsight  - the gear whose theta x frequency is nearest the true speed at every sample (a floor).
// Headline: per-outage DISTANCE error (|distance synthesized - distance driven| / distance driven, outages
// of at least 100 m), median and p95; beside it the speed error per sample (km/h), median and p95.
// Outages: 60 s, the first 120 s into a drive, then every 180 s (bench/outage_protocol.hpp).
//
// Sets (never choose a design on the report set):
//   real logs: the Etios (Carloop OBD) is the tuning car; Louisville (Torque, 1 Hz GPS) and the Swift are
//     report cars. Each car: fit on some drives, replay the others (two folds). A run prints one set only.
//   simulated: the 7 manual presets and random vehicles (sim::random_vehicle), every style, made harder than
//     the road: skip downshifts under braking, heavy-tailed (Student t, 3 degrees of freedom) speed and
//     frequency noise, a cold engine, and at the GPS cadences GPS speed 0.2-1.0 s late (drawn per drive) and
//     the frequency tracker's gaps and readings on another line (bench/outage/simulated.cpp); --easy-sim
//     gives every drive's GPS 0.5 s late and no tracker failures instead. --sim-observation lag|gaps|lines
//     turns on one part of the harder observation alone (the others as --easy-sim has them, the part drawn
//     as with every part on), `all` (the default) every part, `none` none (= --easy-sim). Cadences: the
//     daemon's (frequency every 0.1 s, a 1 Hz fix given at each hop until the next), 1 Hz, OBD polled every 1
//     s (a logging app's rows: integer km/h and rpm, each polled at its own instant within the round's first
//     half), every 2 s, a phone OBD app every 5 s. Seeds: tuning 1..N, report 1001..1000+N; --first-seed S
//     takes S..S+N-1 instead (random vehicles S+500..), for seeds never used by any decision (a fresh
//     report).
// With --require NAME<=VALUE (bench/requirements.hpp) the daemon's synthesis' figures are held to thresholds.
// --synth KEY=VALUE sets a SynthTuning field of the daemon's synthesis for the run (repeatable; VALUE a
// number, "inf", or another field's name). --ablate runs the set once as tuned and once per rule of the
// synthesis with that rule absent (kRules: the setting that switches it off), and prints one row per rule:
// the per-outage distance error, median / p95, on every real car and cadence of the set, and its change;
// --rule SETTING (repeatable) keeps only the rules switched off by that setting. --fits prints each
// simulated vehicle's fitted thetas beside the true ones on stderr, and per cadence how many fits found
// another gear count than the car's; --fit-minutes fits the simulated vehicles' models on a mixed drive of
// M minutes instead of 40; --gps-hz N gives the daemon's cadence a receiver of N fixes a second (1, 2, 5 or
// 10; each fix as late as the drive's GPS, the model still fitted on one pair a second). --wide draws the
// random vehicles from sim::wide_vehicle (3-9 gears, diesels, motorcycles, irregular ladders) instead of
// sim::random_vehicle, for robustness; --random-only leaves the presets out (the random vehicles' figures
// alone). --worst PCT lists every outage of the daemon's synthesis erring beyond PCT % with its failure mode
// (outage_cause) and, per line, each mode's share of the error. --debug CAR STYLE FROM TO prints both
// filters' beliefs per row from FROM to TO s of that drive, and the daemon's synthesis' track (speed,
// acceleration) at each position of its ladder (CAR a simulated car's name, or NAME/sSEED for one seed; STYLE
// 0 mixed, 1 urban, 2 jam, 3 highway).
// --calibration prints per line how well the daemon's synthesis' belief knows its odds over the outage
// samples: the belief in modes slower and faster than the truth (by 5 %, at least 0.5 m/s), the signed error
// of its mean speed and of the output, and the belief below / above its most probable mode's speed against
// how often the truth lies there; on simulated drives (true gear known) the belief in the true mode and that
// mode's own speed error, the belief in slower / faster gears and in no gear while in gear, how often the
// most probable mode is a slower / a faster gear, the Brier score of the modes' probabilities and the log
// score of the true mode's (nats), and a reliability table (each mode's probability by tenths: its mean, how
// often that mode is the truth, count; declutched and moving off one mode).
//
// --log FILE (repeatable) scores the logs of one car of the user's instead of the set's real cars (any
// format `gearpulse fit` reads; --row-seconds S for logs without a time column): fitted on the logs in
// even places, replayed on those in odd places, and the other way round (one log: its halves).
//
// Usage: bench_outage [--set tuning|report] [--seeds N] [--random N] [--first-seed S] [--cadence K]
// [--real-only] [--sim-only]
//                     [--synth KEY=VALUE]... [--ablate [--rule SETTING]...] [--trace FILE] [--fits]
//                     [--fit-minutes M] [--gps-hz N] [--wide] [--random-only] [--easy-sim]
//                     [--sim-observation PART] [--worst PCT] [--calibration] [--debug CAR STYLE FROM TO]
//                     [--log FILE]... [--row-seconds S] [DATA_DIR]
//
// The bench's parts are in bench/outage/ (outage.hpp: the shared types and which file does what).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "bench/outage/outage.hpp"
#include "bench/requirements.hpp"
#include "bench/synth_settings.hpp"
#include "core/sample_io.hpp"
#include "core/speed_synth.hpp"

namespace fs = std::filesystem;
using namespace gearpulse::bench;
using namespace gearpulse::bench::outage;

int main(int argc, char** argv) {
  Requirements required;  // --require NAME<=VALUE (bench/requirements.hpp)
  if (!required.parse(argc, argv)) return 2;
  Options opt;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> trace(nullptr, &std::fclose);
  bool report_set = false, real = true, simu = true, ablation = false;
  int seeds = 2, randoms = 7;
  gearpulse::SynthTuning tuning;
  std::vector<std::string> only;
  fs::path root = GEARPULSE_REAL_DATA_DIR;
  std::vector<fs::path> given;
  double row_seconds = 1.0;
  for (int i = 1; i < argc; ++i) {
    const std::string_view a = argv[i];
    if (a == "--set" && i + 1 < argc) {
      report_set = std::string_view(argv[++i]) == "report";
    } else if (a == "--seeds" && i + 1 < argc) {
      seeds = std::atoi(argv[++i]);
    } else if (a == "--random" && i + 1 < argc) {
      randoms = std::atoi(argv[++i]);
    } else if (a == "--first-seed" && i + 1 < argc) {
      opt.first_seed = std::atol(argv[++i]);
      if (opt.first_seed < 1) {
        std::fprintf(stderr, "--first-seed wants a seed of 1 or more: %s\n", argv[i]);
        return 2;
      }
    } else if (a == "--trace" && i + 1 < argc) {
      trace.reset(std::fopen(argv[++i], "w"));
      opt.trace = trace.get();
    } else if (a == "--cadence" && i + 1 < argc) {
      opt.cadence = std::atol(argv[++i]);
    } else if (a == "--debug" && i + 4 < argc) {
      opt.debug_car = argv[++i];
      opt.debug_style = std::atoi(argv[++i]);
      opt.debug_from = std::atof(argv[++i]);
      opt.debug_to = std::atof(argv[++i]);
    } else if (a == "--synth" && i + 1 < argc) {
      if (!apply_settings(tuning, argv[++i])) {
        std::fprintf(stderr, "--synth wants KEY=VALUE, KEY a SynthTuning field: %s\n", argv[i]);
        return 2;
      }
    } else if (a == "--ablate") {
      ablation = true;
    } else if (a == "--rule" && i + 1 < argc) {
      only.emplace_back(argv[++i]);
    } else if (a == "--worst" && i + 1 < argc) {
      opt.worst = std::atof(argv[++i]);
    } else if (a == "--calibration") {
      opt.calibration = true;
    } else if (a == "--wide") {
      opt.wide = true;
    } else if (a == "--random-only") {
      opt.presets = false;
    } else if (a == "--fits") {
      opt.fits = true;
    } else if (a == "--easy-sim") {
      opt.observation = {false, false, false};
    } else if (a == "--sim-observation" && i + 1 < argc) {
      const std::string_view parts = argv[++i];
      opt.observation = {parts == "all" || parts == "lag", parts == "all" || parts == "gaps",
                         parts == "all" || parts == "lines"};
      if (parts != "none" && opt.observation.none()) {
        std::fprintf(stderr, "--sim-observation wants lag, gaps, lines, all or none: %s\n", argv[i]);
        return 2;
      }
    } else if (a == "--gps-hz" && i + 1 < argc) {
      opt.gps_hz = std::atoi(argv[++i]);
      if (opt.gps_hz != 1 && opt.gps_hz != 2 && opt.gps_hz != 5 && opt.gps_hz != 10) {
        std::fprintf(stderr, "--gps-hz wants 1, 2, 5 or 10 fixes a second: %s\n", argv[i]);
        return 2;
      }
    } else if (a == "--fit-minutes" && i + 1 < argc) {
      opt.fit_minutes = std::atof(argv[++i]);
    } else if (a == "--log" && i + 1 < argc) {
      given.emplace_back(argv[++i]);
    } else if (a == "--row-seconds" && i + 1 < argc) {
      row_seconds = std::atof(argv[++i]);
      if (!(std::isfinite(row_seconds) && row_seconds > 0.0)) {
        std::fprintf(stderr, "--row-seconds wants seconds above 0: %s\n", argv[i]);
        return 2;
      }
    } else if (a == "--real-only") {
      simu = false;
    } else if (a == "--sim-only") {
      real = false;
    } else {
      root = a;
    }
  }
  const auto start = std::chrono::steady_clock::now();
  if (real && given.empty() && !fs::exists(root / (report_set ? "torque-louisville" : "carloop-etios"))) {
    std::printf("GEARPULSE_SKIP: bench_outage: no real logs under %s\n", root.c_str());
    return 0;
  }
  Workload w;
  try {
    if (real && !given.empty())
      given_logs(given, row_seconds, w);
    else if (real)
      real_logs(root, report_set, w);
  } catch (const gearpulse::SampleFileError& e) {
    std::fprintf(stderr, "bench_outage: %s\n", e.what());
    return 2;
  }
  if (simu) simulated(report_set, seeds, randoms, opt, w);
  if (ablation) {
    opt.candidate = false;
    ablate(w, tuning, only, opt);
  } else {
    const Outcome o = evaluate(w, tuning, opt);
    print_outcome(w, o, required);
    if (opt.worst > 0.0) print_worst(w, o, opt.worst);
    if (opt.calibration) print_calibration(w, o);
  }
  std::printf("\n(%.1f s)\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  return ablation ? 0 : required.exit_status();
}
