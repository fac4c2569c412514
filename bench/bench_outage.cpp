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
//     the road: skip downshifts under braking, GPS speed 0.5 s late, heavy-tailed (Student t, 3 degrees of
//     freedom) speed and frequency noise, a cold engine. Cadences: the daemon's (frequency every 0.1 s, a 1
//     Hz fix given at each hop until the next), 1 Hz, OBD polled every 2 s, a phone OBD app every 5 s. Seeds:
//     tuning 1..N, report 1001..1000+N.
// With --require NAME<=VALUE (bench/requirements.hpp) the daemon's synthesis' figures are held to thresholds.
// --synth KEY=VALUE sets a SynthTuning field of the daemon's synthesis for the run (repeatable; VALUE a
// number, "inf", or another field's name). --ablate runs the set once as tuned and once per rule of the
// synthesis with that rule absent (kRules: the setting that switches it off), and prints one row per rule:
// the per-outage distance error, median / p95, on every real car and cadence of the set, and its change;
// --rule SETTING (repeatable) keeps only the rules switched off by that setting. --fits prints each
// simulated vehicle's fitted thetas beside the true ones on stderr; --fit-minutes fits the simulated
// vehicles' models on a mixed drive of M minutes instead of 40. --worst PCT lists every outage of the
// daemon's synthesis erring beyond PCT % with its failure mode (outage_cause) and, per line, each mode's
// share of the error. --debug CAR STYLE FROM TO prints both filters' beliefs per row from FROM to TO s of
// that drive, and the daemon's synthesis' track (speed, acceleration) at each position of its ladder (CAR
// a simulated car's name, or NAME/sSEED for one seed; STYLE 0 mixed, 1 urban, 2 jam, 3 highway).
//
// --log FILE (repeatable) scores the logs of one car of the user's instead of the set's real cars (any
// format `gearpulse fit` reads; --row-seconds S for logs without a time column): fitted on the logs in
// even places, replayed on those in odd places, and the other way round (one log: its halves).
//
// Usage: bench_outage [--set tuning|report] [--seeds N] [--random N] [--cadence K] [--real-only] [--sim-only]
//                     [--synth KEY=VALUE]... [--ablate [--rule SETTING]...] [--trace FILE] [--fits]
//                     [--fit-minutes M] [--worst PCT] [--debug CAR STYLE FROM TO] [--log FILE]...
//                     [--row-seconds S] [DATA_DIR]
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "bench/outage_protocol.hpp"
#include "bench/requirements.hpp"
#include "core/estimator.hpp"
#include "core/imm_speed_synth.hpp"
#include "core/sample_io.hpp"
#include "core/speed_synth.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace fs = std::filesystem;
namespace sim = gearpulse::sim;
using gearpulse::GearModel;
using gearpulse::Sample;
using namespace gearpulse::bench;

namespace {

constexpr int kMethods = 5;
constexpr const char* kMethodNames[kMethods] = {"gearpulse", "IMM cand.", "keep gear", "hold speed",
                                                "hindsight"};
constexpr double kMinDistance = 100.0;  // m: shorter outages have no meaningful relative distance error

// What a run does beside scoring the set, from the command line.
struct Options {
  std::FILE* trace = nullptr;  // --trace FILE: every outage row
  long cadence = -1;           // --cadence K: only the K-th simulated cadence
  std::string debug_car;       // --debug CAR STYLE FROM TO: both filters' beliefs, per row
  int debug_style = -1;
  double debug_from = 0.0, debug_to = 0.0;
  bool fits = false;          // --fits: each fitted ladder beside the true one, on stderr
  double fit_minutes = 40.0;  // --fit-minutes M: the length of the drive the model is fitted on
  bool candidate = true;      // the candidate IMM filter runs beside the daemon's synthesis
  double worst = 0.0;         // --worst PCT: the daemon's synthesis' outages erring beyond PCT %
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

struct Results {
  std::vector<double> dist[kMethods];   // per outage, %
  std::vector<double> speed[kMethods];  // per sample, km/h
  std::vector<std::string> cause;       // per outage (--worst), the failure mode of the daemon's synthesis
  std::vector<WorstOutage> worst;       // with --worst, the outages beyond it
  void append(const Results& o) {
    for (int m = 0; m < kMethods; ++m) {
      dist[m].insert(dist[m].end(), o.dist[m].begin(), o.dist[m].end());
      speed[m].insert(speed[m].end(), o.speed[m].begin(), o.speed[m].end());
    }
    cause.insert(cause.end(), o.cause.begin(), o.cause.end());
    worst.insert(worst.end(), o.worst.begin(), o.worst.end());
  }
};

// What the daemon's synthesis did at one row of an outage, for --worst.
struct Step {
  double speed = 0.0;
  int gear = 0;
};

// The model's gear (index + 1) whose theta lies within `tolerance` of `theta` in ratio, 0 if none.
int gear_near(const GearModel& m, double theta, double tolerance) {
  int best = 0;
  double err = tolerance;
  for (std::size_t i = 0; i < m.gears.size(); ++i) {
    const double e = std::abs(std::log(m.gears[i].theta / theta));
    if (e < err) best = static_cast<int>(i) + 1, err = e;
  }
  return best;
}

// The failure mode of one outage (rows [begin, end) of a drive, `steps` the synthesis' output per row):
// the moment the error sets in (the first row from which the output stays more than 15 % and 1.5 m/s off
// the truth for 3 s, most rows of it) and what the car did around it. Returns {mode, detail}.
std::pair<std::string, std::string> outage_cause(const std::vector<Row>& rows, const std::vector<Step>& steps,
                                                 std::size_t begin, std::size_t end, const GearModel& model,
                                                 const std::vector<double>& true_theta) {
  constexpr double kHold = 3.0;  // s the error must last
  const auto off = [&](std::size_t i) {
    const double e = std::abs(steps[i].speed - rows[i].truth);
    return e > std::max(1.5, 0.15 * rows[i].truth);
  };
  std::size_t onset = end;
  for (std::size_t i = begin; i < end && onset == end; ++i) {
    if (!off(i)) continue;
    std::size_t n = 0, bad = 0, j = i;
    for (; j < end && rows[j].t - rows[i].t < kHold; ++j, ++n)
      bad += off(j) ? 1 : 0;
    if (bad >= 0.8 * static_cast<double>(n) && (j < end || n > 0)) onset = i;
  }
  const double t0 = rows[begin].t;
  if (onset == end) return {"no lasting error (many small ones)", ""};
  const double t_on = rows[onset].t;
  const bool sim = rows[begin].gear >= 0;
  char detail[160];
  std::snprintf(detail, sizeof detail, "%sfrom +%.1f s: out %.1f (g%d) truth %.1f km/h (g%d)",
                t_on - t0 < kHold ? "at outage start, " : "", t_on - t0, steps[onset].speed * kMsToKmh,
                steps[onset].gear, rows[onset].truth * kMsToKmh, rows[onset].gear);
  // The window around the onset: 5 s before it (reaching back before the outage) to 1 s after.
  std::size_t w0 = onset;
  while (w0 > 0 && rows[w0 - 1].t >= t_on - 5.0)
    --w0;
  std::size_t w1 = onset;
  while (w1 + 1 < rows.size() && rows[w1 + 1].t <= t_on + 1.0)
    ++w1;
  double min_truth = rows[onset].truth, declutched = 0.0;
  int jumps = 0, skip = 0;
  for (std::size_t i = w0; i <= w1; ++i) {
    min_truth = std::min(min_truth, rows[i].truth);
    const double dt = i + 1 < rows.size() ? std::min(rows[i + 1].t - rows[i].t, 5.0) : 0.0;
    if (rows[i].gear == 0 && rows[i].truth > 1.0) declutched += dt;
  }
  // Gears engaged through the window (clutch-out rows skipped): shifts and skips.
  int last_gear = 0;
  for (std::size_t i = w0; i <= w1; ++i) {
    if (rows[i].gear <= 0) continue;
    if (last_gear > 0 && rows[i].gear != last_gear) {
      ++jumps;
      if (std::abs(rows[i].gear - last_gear) >= 2) ++skip;
    }
    last_gear = rows[i].gear;
  }
  bool launched = false;  // the car stood within 10 s before the onset and moves at it
  for (std::size_t i = onset; i > 0 && rows[i].t >= t_on - 10.0; --i)
    if (rows[i].truth < 0.3 && rows[onset].truth > 1.0) launched = true;
  // Braking: from 3 s before the onset to 2 s after it the truth lost more than 2 m/s, or it stands in the
  // window.
  double fastest = 0.0;
  bool braking = min_truth < 0.3 && !launched;
  for (std::size_t i = onset; i > 0 && rows[i].t >= t_on - 3.0; --i)
    fastest = std::max(fastest, rows[i].truth);
  for (std::size_t i = onset; i < rows.size() && rows[i].t <= t_on + 2.0; ++i)
    braking = braking || rows[i].truth < fastest - 2.0;
  const bool too_fast = steps[onset].speed > rows[onset].truth;
  const int g_out = steps[onset].gear;
  if (sim) {
    // The fit: the true gear at the onset (or the last engaged) has no gear of the model, or the output's
    // gear is none of the car's.
    int g_true = rows[onset].gear;
    for (std::size_t i = onset; g_true <= 0 && i > w0; --i)
      g_true = rows[i - 1].gear;
    constexpr double kTolerance = 0.04;
    const int g_model = g_true > 0 && static_cast<std::size_t>(g_true) <= true_theta.size()
                            ? gear_near(model, true_theta[static_cast<std::size_t>(g_true - 1)], kTolerance)
                            : -1;
    if (g_model == 0) return {"fit lacks the engaged gear", detail};
    if (g_out > 0) {
      bool real_gear = false;
      for (const double th : true_theta)
        real_gear =
            real_gear ||
            std::abs(std::log(model.gears[static_cast<std::size_t>(g_out - 1)].theta / th)) < kTolerance;
      if (!real_gear) return {"fit invented the output's gear", detail};
    }
    if (braking && too_fast && g_out == 0) return {"braking declutched: deceleration lost", detail};
    if (launched) return {"launch", detail};
    if (braking) return {"braking: other", detail};
    const int g_now = rows[onset].gear > 0 ? g_model : 0;  // the model's gear engaged at the onset, 0: none
    if (g_out > 0 && g_now > 0 && g_out != g_now) {
      if (skip > 0) return {"wrong gear after a skip shift", detail};
      if (jumps > 0) return {"wrong gear after a shift", detail};
      return {"wrong gear, steady driving", detail};
    }
    if (g_out == 0 && g_now > 0) return {"in gear, read as declutched", detail};
    if (declutched >= 1.5 || g_now == 0) return {"declutched: speed drifted", detail};
    return {"other", detail};
  }
  if (braking && too_fast) return {"braking (real log)", detail};
  if (launched) return {"launch (real log)", detail};
  return {"moving (real log)", detail};
}

// Replays rows with outages; a row repeating an OBD logger's held rpm in an outage brings nothing (as
// `gearpulse replay` does).
// `where` names the case for --worst (line, car) and `true_theta` is the simulated car's ladder (empty for a
// real log). Rows from opt.debug_from to `debug_to` s are printed for --debug.
void replay(const std::vector<Row>& rows, const std::shared_ptr<const GearModel>& shared,
            const gearpulse::SynthTuning& tuning, bool live, const Options& opt, double debug_to,
            Results& res, const std::array<std::string, 2>& where, int style,
            const std::vector<double>& true_theta) {
  if (rows.empty()) return;
  const GearModel& model = *shared;
  gearpulse::SpeedSynthesizer synth(shared, tuning);
  gearpulse::ImmSpeedSynthesizer imm(shared);
  gearpulse::ImmLogReplayer imm_replayer(imm);
  const double t0 = rows.front().t;
  double last_gps = 0.0, last_freq = gearpulse::kMissing;
  int kept_gear = -1;
  double dist[kMethods + 1] = {};  // the methods', then the truth's
  double value[kMethods] = {};
  bool was_out = false;
  gearpulse::SynthOutput o, o_imm;
  gearpulse::LogReplayer replayer(synth);
  std::vector<Step> steps(opt.worst > 0.0 ? rows.size() : 0);
  std::size_t out_begin = 0;  // first row of the current outage
  const auto close_outage = [&](std::size_t out_end) {
    if (dist[kMethods] >= kMinDistance) {
      for (int m = 0; m < kMethods; ++m)
        res.dist[m].push_back(100.0 * std::abs(dist[m] - dist[kMethods]) / dist[kMethods]);
      if (opt.worst > 0.0) {
        auto [cause, detail] = outage_cause(rows, steps, out_begin, out_end, model, true_theta);
        const double err = res.dist[0].back();
        res.cause.push_back(cause);
        if (err > opt.worst)
          res.worst.push_back({where[0], where[1], style, rows[out_begin].t - t0, err,
                               100.0 * (dist[0] - dist[kMethods]) / dist[kMethods], res.dist[2].back(),
                               res.dist[4].back(), std::move(cause), std::move(detail)});
      }
    }
    std::fill(std::begin(dist), std::end(dist), 0.0);
  };
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const bool out = in_outage(r.t - t0);
    const double gps = out ? gearpulse::kMissing : r.gps;
    // Live, as the daemon steps at every hop; a log, as `gearpulse replay` does.
    o = live ? synth.step(r.t, gps, r.freq, r.gps_new) : replayer.step({r.t, gps, r.freq});
    if (opt.candidate)
      o_imm = live ? imm.step(r.t, gps, r.freq, r.gps_new) : imm_replayer.step({r.t, gps, r.freq});
    if (opt.debug_from < debug_to && r.t - t0 >= opt.debug_from && r.t - t0 <= debug_to) {
      const auto& flt = imm.filter();
      if (r.t - t0 - opt.debug_from < 0.15) {
        const auto& h = imm.habits();
        std::fprintf(stderr, "idle %.1f/%.2f bands:", h.idle, h.idle_sd);
        for (int g = 1; g <= static_cast<int>(model.gears.size()); ++g)
          std::fprintf(stderr, " %.1f/%.2f", std::exp(h.gear_revs_mean[static_cast<std::size_t>(g)]),
                       h.gear_revs_sd[static_cast<std::size_t>(g)]);
        std::fprintf(stderr, " sigma_freq %.2f\n", model.sigma_freq);
      }
      std::fprintf(stderr, "t %.1f %s truth %.1f g %d f %.1f | out %.1f p:", r.t - t0, out ? "OUT" : "gps",
                   r.truth, r.gear, r.freq, o_imm.speed);
      for (int m = 0; m < flt.modes(); ++m)
        std::fprintf(stderr, " %.2f(%.1f~%.1f)", flt.probability(m), flt.track(m).v,
                     std::sqrt(flt.track(m).pvv));
      // The daemon's synthesis: its output and its belief (0 = no gear, then gears 1..M).
      std::fprintf(stderr, " || synth %.1f g%d p:", o.speed, o.gear);
      for (int m = 0; m <= static_cast<int>(model.gears.size()); ++m)
        std::fprintf(stderr, " %.2f", synth.mode_probability(m));
      // ... and what it carries at each position of its ladder: speed m/s, acceleration ~ its sd m/s^2.
      for (int m = 0; m <= synth.ladder_gears() + 1; ++m) {
        const auto x = synth.mode_track(m);
        std::fprintf(stderr, " [%d %.1f %.2f~%.2f]", m, x.speed, x.accel, x.accel_sd);
      }
      std::fprintf(stderr, "\n");
    }
    if (std::isfinite(r.freq)) last_freq = r.freq;
    if (!steps.empty()) steps[i] = {o.speed, o.gear};
    if (!out) {
      if (was_out) close_outage(i);
      was_out = false;
      if (std::isfinite(gps)) {
        last_gps = gps;
        kept_gear = gps > 1.0 && std::isfinite(last_freq) ? nearest_gear(model, gps, last_freq) : -1;
      }
      continue;
    }
    if (!was_out) out_begin = i;
    was_out = true;
    const double f = last_freq;
    value[0] = o.speed;
    value[1] = o_imm.speed;
    value[2] = kept_gear >= 0 && std::isfinite(f) ? model.gears[static_cast<std::size_t>(kept_gear)].theta * f
                                                  : last_gps;
    value[3] = last_gps;
    value[4] = std::isfinite(f) && !model.gears.empty() ? hindsight_speed(model, r.truth, f) : last_gps;
    const double next_t = i + 1 < rows.size() ? rows[i + 1].t : r.t;
    const double dt = std::min(next_t - r.t, 5.0);
    for (int m = 0; m < kMethods; ++m) {
      dist[m] += value[m] * dt;
      res.speed[m].push_back(std::abs(value[m] - r.truth) * kMsToKmh);
    }
    dist[kMethods] += r.truth * dt;
    if (opt.trace !=
        nullptr)  // t, truth, freq, then the candidate's gear, speed and belief, keep gear, hindsight
      std::fprintf(opt.trace, "%.1f,%.2f,%.2f,%d,%.2f,%.2f,%.2f,%.2f,%d,%.2f\n", r.t - t0, r.truth * kMsToKmh,
                   f, o_imm.gear, o_imm.speed * kMsToKmh, value[2] * kMsToKmh, value[4] * kMsToKmh,
                   imm.mode_probability(o_imm.gear), r.gear, o.speed * kMsToKmh);
  }
  if (was_out) close_outage(rows.size());
}

void print_header() {
  std::printf("%-34s %5s |", "", "outs");
  for (const char* n : kMethodNames)
    std::printf(" %-13s", n);
  std::printf("| speed km/h:");
  for (const char* n : kMethodNames)
    std::printf(" %-12s", n);
  std::printf("\n%-34s %5s |", "", "");
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %-13s", "dist% med/p95");
  std::printf("|            ");
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %-12s", "med/p95");
  std::printf("\n");
}

// Reports the daemon's synthesis' figures of a set as NAME_dist_med_pct, NAME_dist_p95_pct and their
// differences from keeping the gear (NAME_dist_med_minus_keep, NAME_dist_p95_minus_keep: below 0 is better).
void report(const std::string& name, const Results& r, Requirements& required) {
  const double med = quantile(r.dist[0], 0.5), p95 = quantile(r.dist[0], 0.95);
  required.report(name + "_dist_med_pct", med);
  required.report(name + "_dist_p95_pct", p95);
  required.report(name + "_dist_med_minus_keep", med - quantile(r.dist[2], 0.5));
  required.report(name + "_dist_p95_minus_keep", p95 - quantile(r.dist[2], 0.95));
}

void print_line(const std::string& label, const Results& r) {
  std::printf("%-34s %5zu |", label.c_str(), r.dist[0].size());
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %5.2f/%6.2f ", quantile(r.dist[m], 0.5), quantile(r.dist[m], 0.95));
  std::printf("|            ");
  for (int m = 0; m < kMethods; ++m)
    std::printf(" %5.2f/%5.2f ", quantile(r.speed[m], 0.5), quantile(r.speed[m], 0.95));
  std::printf("\n");
  std::fflush(stdout);
}

// ---- the workload: every replay of a run, built once ----
// Fits and simulated drives do not depend on the synthesis' tuning, so --ablate replays the same cases
// under every tuning it compares.

constexpr const char* kStyleNames[4] = {"mixed", "urban", "jam", "highway"};

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

Outcome evaluate(const Workload& w, const gearpulse::SynthTuning& tuning, const Options& opt) {
  Outcome o;
  o.all.resize(w.lines.size());
  o.styles.resize(w.lines.size());
  for (const Case& c : w.cases) {
    Results r;
    if (opt.trace != nullptr) std::fprintf(opt.trace, "# %s %d\n", c.car.c_str(), c.style);
    // A simulated case is named CAR/sSEED; --debug CAR takes every seed of the car.
    const std::string name = c.seed > 0 ? c.car + "/s" + std::to_string(c.seed) : c.car;
    const bool debugged = (c.car == opt.debug_car || name == opt.debug_car) && c.style == opt.debug_style;
    replay(c.rows, c.model, tuning, c.live, opt, debugged ? opt.debug_to : 0.0, r,
           {w.lines[c.line].label, name}, c.style, c.true_theta);
    o.styles[c.line][static_cast<std::size_t>(c.style)].append(r);
    o.all[c.line].append(r);
  }
  return o;
}

void print_outcome(const Workload& w, const Outcome& o, Requirements& required) {
  for (std::size_t l = 0; l < w.lines.size(); ++l) {
    const Line& line = w.lines[l];
    if (!line.title.empty()) {
      std::printf("\n%s\n", line.title.c_str());
      print_header();
    }
    if (line.styles) {
      for (std::size_t s = 0; s < 4; ++s)
        print_line(line.label + ", " + kStyleNames[s], o.styles[l][s]);
      print_line(line.label + ", ALL", o.all[l]);
    } else {
      print_line(line.label, o.all[l]);
    }
    report(line.key, o.all[l], required);
  }
}

// --worst: every outage of the daemon's synthesis beyond `worst` %, worst first, with its failure mode;
// then per line, per failure mode: its outages, those beyond `worst` and beyond the line's p95, and the p95
// the line would have were that mode's outages as good as the hindsight gear.
void print_worst(const Workload& w, const Outcome& o, double worst) {
  for (std::size_t l = 0; l < w.lines.size(); ++l) {
    const Results& r = o.all[l];
    if (r.cause.size() != r.dist[0].size() || r.dist[0].empty()) continue;
    std::vector<WorstOutage> beyond_worst = r.worst;
    std::sort(beyond_worst.begin(), beyond_worst.end(),
              [](const auto& a, const auto& b) { return a.err > b.err; });
    const double p95 = quantile(r.dist[0], 0.95);
    std::printf("\n%s: %zu outages, p95 %.2f %%, %zu beyond %g %% (error, keep gear, hindsight %%)\n",
                w.lines[l].label.c_str(), r.dist[0].size(), p95, beyond_worst.size(), worst);
    for (const WorstOutage& x : beyond_worst)
      std::printf("  %+7.1f %6.1f %5.1f  %-16s %-8s t %6.0f  %-36s %s\n", x.signed_err, x.keep, x.hindsight,
                  x.car.c_str(), kStyleNames[x.style], x.start, x.cause.c_str(), x.detail.c_str());
    std::vector<std::string> causes = r.cause;
    std::sort(causes.begin(), causes.end());
    causes.erase(std::unique(causes.begin(), causes.end()), causes.end());
    // The error beyond the target (5 %), summed over the outages: each mode's share of it.
    constexpr double kTarget = 5.0;
    double excess = 0.0;
    for (const double e : r.dist[0])
      excess += std::max(e - kTarget, 0.0);
    std::printf("  %-44s %5s %6s %5s %13s %13s\n", "failure mode", "outs", ">worst", ">p95", "% err > 5 %",
                "p95 if fixed");
    for (const std::string& c : causes) {
      int n = 0, beyond = 0, above = 0;
      double mine = 0.0;
      std::vector<double> fixed = r.dist[0];
      for (std::size_t k = 0; k < r.cause.size(); ++k) {
        if (r.cause[k] != c) continue;
        ++n;
        beyond += r.dist[0][k] > worst ? 1 : 0;
        above += r.dist[0][k] > p95 ? 1 : 0;
        mine += std::max(r.dist[0][k] - kTarget, 0.0);
        fixed[k] = r.dist[4][k];
      }
      std::printf("  %-44s %5d %6d %5d %13.1f %13.2f\n", c.c_str(), n, beyond, above,
                  excess > 0.0 ? 100.0 * mine / excess : 0.0, quantile(fixed, 0.95));
    }
  }
}

// ---- real logs ----

std::vector<std::vector<Sample>> read_logs(const fs::path& dir, const std::string& prefix) {
  std::vector<std::vector<Sample>> logs;
  if (!fs::exists(dir)) return logs;
  std::vector<fs::path> paths;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".csv" && e.path().filename().string().rfind(prefix, 0) == 0)
      paths.push_back(e.path());
  std::sort(paths.begin(), paths.end());
  for (const auto& p : paths) {
    std::ifstream in(p, std::ios::binary);
    logs.push_back(gearpulse::read_samples(in, p.string()).samples);
  }
  return logs;
}

std::vector<Row> rows_of(const std::vector<Sample>& samples) {
  std::vector<Row> rows;
  for (const Sample& s : samples)
    if (s.has_speed()) rows.push_back({s.t, s.speed, s.freq, s.speed, true});
  return rows;
}

void fold(const std::vector<std::vector<Sample>>& train, const std::vector<std::vector<Sample>>& test,
          Workload& w) {
  std::vector<Sample> pooled;
  for (const auto& l : train)
    pooled.insert(pooled.end(), l.begin(), l.end());
  const auto model = std::make_shared<const GearModel>(gearpulse::fit_gear_model(pooled, {}).model);
  // Each replayed log is named KEY#N (N counts the line's logs), for --worst and --debug.
  for (const auto& l : test) {
    std::size_t n = 0;
    for (const Case& c : w.cases)
      n += c.line == w.lines.size() - 1 ? 1 : 0;
    w.cases.push_back({w.lines.size() - 1,
                       0,
                       w.lines.back().key + "#" + std::to_string(n),
                       rows_of(l),
                       model,
                       false,
                       {},
                       0});
  }
}

std::pair<std::vector<std::vector<Sample>>, std::vector<std::vector<Sample>>> halves(std::vector<Sample> all,
                                                                                     double row_s) {
  for (Sample& s : all)
    s.t *= row_s;
  const auto half = static_cast<long>(all.size() / 2);
  return {{{all.begin(), all.begin() + half}}, {{all.begin() + half, all.end()}}};
}

// The tuning set's car (the Etios) or the report set's (Louisville, the Swift), never both in one run: the
// figures a design is chosen on are not printed beside those that report it.
void real_logs(const fs::path& root, bool report_set, Workload& w) {
  std::string title = std::string("Real logs, ") + (report_set ? "REPORT" : "TUNING") +
                      " set (fit on some drives of a car, replay its others)";
  const auto add_line = [&](const char* label, const char* key) {
    w.lines.push_back({title, label, key, false});
    title.clear();
  };
  if (!report_set) {
    const auto drives = read_logs(root / "carloop-etios", "drive");
    const auto longs = read_logs(root / "carloop-etios", "long");
    if (!drives.empty() && !longs.empty()) {
      add_line("TUNING Etios (OBD ~1.8 s)", "etios");
      fold(drives, longs, w);
      fold(longs, drives, w);
    }
    return;
  }
  const auto louis = read_logs(root / "torque-louisville", "");
  if (!louis.empty()) {
    const auto [a, b] = halves(louis.front(), 1.0);
    add_line("REPORT Louisville (1 Hz GPS)", "louisville");
    fold(a, b, w);
    fold(b, a, w);
  }
  const auto swift = read_logs(root / "swift-147", "");
  for (const double row_s : {1.0, 2.0}) {
    if (swift.empty()) break;
    const auto [a, b] = halves(swift.front(), row_s);
    if (row_s == 1.0)
      add_line("REPORT Swift (1 s per row)", "swift_1s");
    else
      add_line("REPORT Swift (2 s per row)", "swift_2s");
    fold(a, b, w);
    fold(b, a, w);
  }
}

// Logs a user gives (--log, repeatable): one car's drives. Two folds: the logs in even places against
// those in odd places, each fitted on one and replayed on the other; a single log is split in halves.
void given_logs(const std::vector<fs::path>& paths, double row_s, Workload& w) {
  gearpulse::ReadOptions options;
  options.row_seconds = row_s;
  std::vector<std::vector<Sample>> logs;
  for (const fs::path& p : paths) {
    std::ifstream in(p, std::ios::binary);
    if (!in) throw gearpulse::SampleFileError(p.string() + ": cannot open");
    logs.push_back(gearpulse::read_samples(in, p.string(), options).samples);
  }
  w.lines.push_back({"Logs given (fit on some, replay the others)",
                     logs.size() == 1 ? "the log's halves" : "even against odd logs", "given", false});
  if (logs.size() == 1) {
    const auto [a, b] = halves(logs.front(), 1.0);
    fold(a, b, w);
    fold(b, a, w);
    return;
  }
  std::vector<std::vector<Sample>> even, odd;
  for (std::size_t i = 0; i < logs.size(); ++i)
    (i % 2 == 0 ? even : odd).push_back(std::move(logs[i]));
  fold(even, odd, w);
  fold(odd, even, w);
}

// ---- simulated vehicles ----

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

// ---- the synthesis' tuning: --synth KEY=VALUE and --ablate ----

struct Field {
  const char* name;
  double gearpulse::SynthTuning::*member;
};
#define GEARPULSE_FIELD(name)            \
  Field {                                \
#name, &gearpulse::SynthTuning::name \
  }
constexpr Field kFields[] = {
    GEARPULSE_FIELD(accel_sigma),
    GEARPULSE_FIELD(accel_time),
    GEARPULSE_FIELD(coast_accel),
    GEARPULSE_FIELD(coast_sigma),
    GEARPULSE_FIELD(coast_time),
    GEARPULSE_FIELD(stop_speed),
    GEARPULSE_FIELD(stop_accel),
    GEARPULSE_FIELD(launch_accel),
    GEARPULSE_FIELD(launch_sigma),
    GEARPULSE_FIELD(gear_dwell),
    GEARPULSE_FIELD(engage_rate),
    GEARPULSE_FIELD(launch_rate),
    GEARPULSE_FIELD(bite_rate),
    GEARPULSE_FIELD(launch_second),
    GEARPULSE_FIELD(skip_share),
    GEARPULSE_FIELD(evidence_time),
    GEARPULSE_FIELD(idle_weight),
    GEARPULSE_FIELD(lugging_first),
    GEARPULSE_FIELD(lugging_other),
    GEARPULSE_FIELD(launch_gear_time),
    GEARPULSE_FIELD(revs_habit),
    GEARPULSE_FIELD(shift_comfort),
    GEARPULSE_FIELD(min_speed_sigma),
    GEARPULSE_FIELD(min_freq_rel),
    GEARPULSE_FIELD(stationary_speed),
    GEARPULSE_FIELD(max_gap),
    GEARPULSE_FIELD(hold_time),
    GEARPULSE_FIELD(hedge_share),
    GEARPULSE_FIELD(output_quantile),
    GEARPULSE_FIELD(climb_cost),
    GEARPULSE_FIELD(declutch_time),
    GEARPULSE_FIELD(clutch_track_share),
    GEARPULSE_FIELD(leave_cap),
    GEARPULSE_FIELD(bite_gap),
    GEARPULSE_FIELD(jump_reopen),
    GEARPULSE_FIELD(downshift_band),
    GEARPULSE_FIELD(dwell_by_use),
    GEARPULSE_FIELD(warm_floor),
    GEARPULSE_FIELD(rolling_idle),
    GEARPULSE_FIELD(gear_shift_points),
    GEARPULSE_FIELD(idle_on_move),
    GEARPULSE_FIELD(pull_transfer),
    GEARPULSE_FIELD(gps_accel_clip),
    GEARPULSE_FIELD(lost_gear_cost),
    GEARPULSE_FIELD(launch_fade),
    GEARPULSE_FIELD(rest_output),
    GEARPULSE_FIELD(seen_gear_fixes),
    GEARPULSE_FIELD(idle_braking),
    GEARPULSE_FIELD(idle_braking_prior),
    GEARPULSE_FIELD(first_gear_idle_speed),
    GEARPULSE_FIELD(declutch_brake_spread),
    GEARPULSE_FIELD(predict_lower_gears),
    GEARPULSE_FIELD(fitted_lower_gears),
    GEARPULSE_FIELD(speed_lag),
    GEARPULSE_FIELD(speed_lag_prior),
    GEARPULSE_FIELD(speed_lag_significance),
};
#undef GEARPULSE_FIELD

const Field* field_named(std::string_view name) {
  for (const Field& f : kFields)
    if (name == f.name) return &f;
  return nullptr;
}

// Applies "KEY=VALUE[,KEY=VALUE...]": VALUE is a number ("inf" too) or another field's name (its value).
bool apply_settings(gearpulse::SynthTuning& t, std::string_view settings) {
  while (!settings.empty()) {
    const std::size_t comma = settings.find(',');
    const std::string_view one = settings.substr(0, comma);
    settings = comma == std::string_view::npos ? std::string_view{} : settings.substr(comma + 1);
    const std::size_t eq = one.find('=');
    const Field* key = eq == std::string_view::npos ? nullptr : field_named(one.substr(0, eq));
    if (key == nullptr) return false;
    const std::string value(one.substr(eq + 1));
    if (const Field* other = field_named(value)) {
      t.*(key->member) = t.*(other->member);
      continue;
    }
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    if (value.empty() || *end != '\0') return false;
    t.*(key->member) = v;
  }
  return true;
}

// The rules of the daemon's synthesis, each with the setting at which it is absent. Physical quantities
// (accelerations, rates, noise floors) are not rules and are not switched off.
struct Rule {
  const char* name;
  const char* neutral;
};
constexpr Rule kRules[] = {
    {"hedge: output leans toward the contenders' speed", "hedge_share=0"},
    {"quantile: output mode above the belief's median", "output_quantile=0.5"},
    {"revs habit: steady revs scored by the gear's band", "revs_habit=0"},
    {"shift comfort: shifts toward the new gear's band", "shift_comfort=0"},
    {"lugging: no gear below the revs its driver holds it at", "lugging_first=1,lugging_other=1"},
    {"creeping: first gear exempt from lugging", "lugging_first=lugging_other"},
    {"launch gear: first gear left the sooner", "launch_gear_time=inf"},
    {"stop: slow declutched car brakes to rest", "stop_speed=0"},
    {"skip shifts", "skip_share=0"},
    {"second-gear launches", "launch_second=0"},
    {"climb: climbing revs cost the clutch", "climb_cost=0"},
    {"declutch caught within a long step", "declutch_time=0"},
    {"clutch follows the gear at hops", "clutch_track_share=0"},
    {"leave cap: gear hazard capped", "leave_cap=inf"},
    {"bite gap: biting clutch's spread", "bite_gap=0"},
    {"jump reopen: acceleration reopened", "jump_reopen=0"},
    {"downshift band: gear's revs band", "downshift_band=0"},
    {"dwell by use: rarely used gears left sooner", "dwell_by_use=0"},
    {"warm floor: idle down to the fit's warm idle", "warm_floor=0"},
    {"rolling idle: declutched revs held on the move", "rolling_idle=0"},
    {"per-gear shift revs", "gear_shift_points=0"},
    {"idle learned on the move", "idle_on_move=0"},
    {"pull transfer: acceleration scaled at a shift", "pull_transfer=0"},
    {"GPS acceleration clip", "gps_accel_clip=0"},
    {"lost gear cost: a gear fades without revs", "lost_gear_cost=0"},
    {"launch fade: no move-off at speed", "launch_fade=0"},
    {"rest output: slow declutched output is 0", "rest_output=0"},
    {"seen gears: a steady ratio off the model is a gear", "seen_gear_fixes=inf"},
    {"idle braking: declutched at idle brakes as learned", "idle_braking=0"},
    {"idle braking prior: the fit's idle braking", "idle_braking_prior=0"},
    {"first gear at idle: a ladder too tall at idle lacks first", "first_gear_idle_speed=inf"},
    {"declutch brake spread: braking uncertain once declutched", "declutch_brake_spread=0"},
    {"lower gears: a ladder lacking first extended below", "predict_lower_gears=0"},
    {"fitted lower gears: the fit's gears below a ladder lacking first", "fitted_lower_gears=0"},
    {"speed lag: a fix is the speed of a moment before", "speed_lag=0"},
    {"speed lag prior: the fit's speed lag until the drive's shows", "speed_lag_prior=0"},
    {"speed lag significance: the drive's best lag from its first fix", "speed_lag_significance=0"},
};

std::string figure(double med, double p95) {
  char b[40];
  std::snprintf(b, sizeof b, "%.2f / %.2f", med, p95);
  return b;
}

// A change of a figure: "0" when it is exactly unchanged, else signed to two decimals (+0.00 is a rise
// below 0.005).
std::string change(double med, double p95) {
  const auto one = [](double d) {
    char b[20];
    if (d == 0.0)
      std::snprintf(b, sizeof b, "0");
    else
      std::snprintf(b, sizeof b, "%+.2f", d);
    return std::string(b);
  };
  return one(med) + " / " + one(p95);
}

// Runs the workload with `base` and once per rule with that rule absent; one markdown row per rule: the
// daemon's synthesis' per-outage distance error (median / p95, %) on every line of the set and its change
// against `base`, and how many of those figures grew.
void ablate(const Workload& w, const gearpulse::SynthTuning& base, const std::vector<std::string>& only,
            const Options& opt) {
  const auto summary = [&](const Outcome& o) {
    std::vector<std::pair<double, double>> f;
    for (const Results& r : o.all)
      f.emplace_back(quantile(r.dist[0], 0.5), quantile(r.dist[0], 0.95));
    return f;
  };
  std::printf(
      "\nAblation: per-outage distance error of the daemon's synthesis, median / p95 %%\n\n| rule | absent "
      "at |");
  for (const Line& l : w.lines)
    std::printf(" %s |", l.label.c_str());
  std::printf(" figures worse |\n|---|---|");
  for (std::size_t l = 0; l < w.lines.size(); ++l)
    std::printf("---|");
  std::printf("---|\n");
  const auto defaults = summary(evaluate(w, base, opt));
  std::printf("| defaults | |");
  for (const auto& [med, p95] : defaults)
    std::printf(" %s |", figure(med, p95).c_str());
  std::printf(" |\n");
  std::fflush(stdout);
  for (const Rule& rule : kRules) {
    if (!only.empty() && std::find(only.begin(), only.end(), rule.neutral) == only.end()) continue;
    gearpulse::SynthTuning t = base;
    if (!apply_settings(t, rule.neutral)) continue;
    const auto f = summary(evaluate(w, t, opt));
    int worse = 0;
    std::printf("| %s | `%s` |", rule.name, rule.neutral);
    for (std::size_t l = 0; l < f.size(); ++l) {
      const double dm = f[l].first - defaults[l].first, dp = f[l].second - defaults[l].second;
      worse += (dm > 0.0 ? 1 : 0) + (dp > 0.0 ? 1 : 0);
      std::printf(" %s |", change(dm, dp).c_str());
    }
    std::printf(" %d of %zu |\n", worse, 2 * f.size());
    std::fflush(stdout);
  }
}

}  // namespace

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
    } else if (a == "--fits") {
      opt.fits = true;
    } else if (a == "--fit-minutes" && i + 1 < argc) {
      opt.fit_minutes = std::atof(argv[++i]);
    } else if (a == "--log" && i + 1 < argc) {
      given.emplace_back(argv[++i]);
    } else if (a == "--row-seconds" && i + 1 < argc) {
      row_seconds = std::atof(argv[++i]);
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
  }
  std::printf("\n(%.1f s)\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  return ablation ? 0 : required.exit_status();
}
