#pragma once
// The parts of the outage bench (bench/bench_outage.cpp holds main() and says what the bench measures and
// how it is run): the workload of a run, built once (real logs: real_logs.cpp; simulated vehicles:
// simulated.cpp), its replay with outages (evaluate.cpp), the printed tables and figures (print.cpp), and
// the synthesis' tuning and ablation (ablation.cpp).
#include <array>
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "bench/requirements.hpp"
#include "core/gear_model.hpp"
#include "core/sample.hpp"
#include "core/speed_synth.hpp"

namespace gearpulse::bench::outage {

// The methods scored, in this order: the daemon's synthesis, the candidate IMM filter, keep gear, hold
// speed, hindsight (print.cpp: kMethodNames).
inline constexpr int kMethods = 5;

// What a run does beside scoring the set, from the command line.
// Which parts of the harder simulated observation are on (--sim-observation; all three by default; none of
// them is --easy-sim: GPS 0.5 s late on every drive, no tracker failures). A part off is as --easy-sim has
// it; the parts on are drawn exactly as with all three.
struct SimObservation {
  bool lag = true;    // GPS 0.2-1.0 s late, drawn per drive (off: 0.5 s)
  bool gaps = true;   // the tracker's gaps
  bool lines = true;  // the tracker's readings on another line
  [[nodiscard]] bool none() const noexcept { return !lag && !gaps && !lines; }
};

struct Options {
  std::FILE* trace = nullptr;  // --trace FILE: every outage row
  long cadence = -1;           // --cadence K: only the K-th simulated cadence
  std::string debug_car;       // --debug CAR STYLE FROM TO: both filters' beliefs, per row
  int debug_style = -1;
  double debug_from = 0.0, debug_to = 0.0;
  bool fits = false;           // --fits: each fitted ladder beside the true one, on stderr
  double fit_minutes = 40.0;   // --fit-minutes M: the length of the drive the model is fitted on
  SimObservation observation;  // --sim-observation, --easy-sim
  bool candidate = true;       // the candidate IMM filter runs beside the daemon's synthesis
  double worst = 0.0;          // --worst PCT: the daemon's synthesis' outages erring beyond PCT %
  long first_seed = -1;  // --first-seed N: simulated seeds N.., random vehicles N+500.. (else the set's)
  bool wide = false;     // --wide: the random vehicles drawn by sim::wide_vehicle, not sim::random_vehicle
  bool presets = true;   // the manual presets beside the random vehicles (--random-only: none)
  bool calibration = false;  // --calibration: how well the daemon's synthesis' belief knows its odds
  int gps_hz = 1;            // --gps-hz N: the daemon cadence's fixes a second (1, 2, 5 or 10)
};

// One replay row: time, the speed given to the synthesis (NaN in an outage or between fixes), whether the
// fix is new, the frequency, and the truth.
struct Row {
  double t = 0.0, gps = gearpulse::kMissing, freq = gearpulse::kMissing, truth = 0.0;
  bool gps_new = true;
  int gear = -1;  // the true gear where known (simulated drives; 0 = clutch out), for the trace
};

// One outage of the daemon's synthesis erring beyond --worst: where it was and what went wrong.
struct WorstOutage {
  std::string line, car;
  int style = 0;
  double start = 0.0;                  // s from the drive's start
  double err = 0.0, signed_err = 0.0;  // %, |distance error| and its sign (+: too far)
  double keep = 0.0, hindsight = 0.0;  // % of the baselines
  std::string cause, detail;
};

// --calibration: the daemon's synthesis' belief against the truth over the outage samples. Every mode's
// probability is binned by tenths against how often that mode is the true one (simulated drives; gears by
// the true ladder, declutched and moving off one mode); `slower` / `faster` sum the belief in modes slower /
// faster than the truth by more than kCalibrationTolerance, `bias` the belief's mean speed minus the truth,
// `out_bias` the output's; `true_bias` the true mode's own speed minus the truth (simulated drives).
struct Calibration {
  std::array<double, 10> p{}, hits{}, count{};
  double samples = 0.0, slower = 0.0, faster = 0.0, bias = 0.0, out_bias = 0.0;
  double labelled = 0.0, true_mode = 0.0, true_bias = 0.0;
  // Brier score of the modes' probabilities against the true mode, and the log score (nats) of the true
  // mode's probability (at least 1e-3), summed over the labelled samples.
  double brier = 0.0, log_score = 0.0;
  // Belief in slower / faster gears while the truth is in gear, and in gears while it is declutched.
  double in_gear = 0.0, slower_gear = 0.0, faster_gear = 0.0, no_gear = 0.0, declutched = 0.0,
         gear_held = 0.0;
  // The belief below / above the speed of its most probable mode, and how often the truth is there.
  double below_lead = 0.0, above_lead = 0.0, truth_below = 0.0, truth_above = 0.0;
  // In gear, how often the most probable mode is a slower / a faster gear, or no gear.
  double lead_slower = 0.0, lead_faster = 0.0, lead_no_gear = 0.0;
  void append(const Calibration& o) {
    for (std::size_t b = 0; b < p.size(); ++b)
      p[b] += o.p[b], hits[b] += o.hits[b], count[b] += o.count[b];
    samples += o.samples, slower += o.slower, faster += o.faster, bias += o.bias, out_bias += o.out_bias;
    labelled += o.labelled, true_mode += o.true_mode, true_bias += o.true_bias;
    brier += o.brier, log_score += o.log_score;
    in_gear += o.in_gear, slower_gear += o.slower_gear, faster_gear += o.faster_gear, no_gear += o.no_gear;
    declutched += o.declutched, gear_held += o.gear_held;
    below_lead += o.below_lead, above_lead += o.above_lead, truth_below += o.truth_below;
    truth_above += o.truth_above, lead_slower += o.lead_slower, lead_faster += o.lead_faster;
    lead_no_gear += o.lead_no_gear;
  }
};
// Share of the truth (at least 0.5 m/s): modes this near the truth's speed are neither slower nor faster.
inline constexpr double kCalibrationTolerance = 0.05;

// The scores of one or more replays, per method.
struct Results {
  std::vector<double> dist[kMethods];   // per outage, %
  std::vector<double> speed[kMethods];  // per sample, km/h
  std::vector<std::string> cause;       // per outage (--worst), the failure mode of the daemon's synthesis
  std::vector<WorstOutage> worst;       // with --worst, the outages beyond it
  Calibration calibration;              // with --calibration
  void append(const Results& o) {
    calibration.append(o.calibration);
    for (int m = 0; m < kMethods; ++m) {
      dist[m].insert(dist[m].end(), o.dist[m].begin(), o.dist[m].end());
      speed[m].insert(speed[m].end(), o.speed[m].begin(), o.speed[m].end());
    }
    cause.insert(cause.end(), o.cause.begin(), o.cause.end());
    worst.insert(worst.end(), o.worst.begin(), o.worst.end());
  }
};

// ---- the workload: every replay of a run, built once ----
// Fits and simulated drives do not depend on the synthesis' tuning, so --ablate replays the same cases
// under every tuning it compares.
struct Line {
  std::string title;    // printed with the header before the line, if not empty
  std::string label;    // a simulated cadence's name (its lines: ", mixed" ... ", ALL")
  std::string key;      // figure names: KEY_dist_med_pct ...
  bool styles = false;  // simulated: one line per style before the ALL line
};

struct Case {
  std::size_t line = 0;
  int style = 0;
  std::string car;  // for --trace and --debug
  std::vector<Row> rows;
  std::shared_ptr<const GearModel> model;
  bool live = false;               // stepped at every row as the daemon does, else as `gearpulse replay` does
  std::vector<double> true_theta;  // the simulated car's ladder (--worst), empty for a real log
  int seed = 0;                    // the simulated drive's seed (1..N, 1001..), 0 for a real log
};

struct Workload {
  std::vector<Line> lines;
  std::vector<Case> cases;
};

struct Outcome {
  std::vector<Results> all;                    // per line
  std::vector<std::array<Results, 4>> styles;  // per line and style (simulated lines)
};

// Real logs (real_logs.cpp): the set's car, or the logs of one car a user gives (--log).
void real_logs(const std::filesystem::path& root, bool report_set, Workload& w);
void given_logs(const std::vector<std::filesystem::path>& paths, double row_s, Workload& w);

// Simulated vehicles (simulated.cpp): every cadence (or --cadence's), car, seed and style of the set.
void simulated(bool report_set, int seeds, int randoms, const Options& opt, Workload& w);

// Replays every case of the workload under `tuning` (evaluate.cpp).
Outcome evaluate(const Workload& w, const gearpulse::SynthTuning& tuning, const Options& opt);

// The tables and figures of an outcome, and --worst's outages and failure modes (print.cpp).
void print_outcome(const Workload& w, const Outcome& o, Requirements& required);
void print_worst(const Workload& w, const Outcome& o, double worst);
void print_calibration(const Workload& w, const Outcome& o);

// --ablate (ablation.cpp); --synth is bench/synth_settings.hpp's apply_settings.
void ablate(const Workload& w, const gearpulse::SynthTuning& base, const std::vector<std::string>& only,
            const Options& opt);

}  // namespace gearpulse::bench::outage
