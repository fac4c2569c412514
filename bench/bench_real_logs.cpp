// Real-log bench: fit gear scales on some drives, replay others with GPS outages blanked out of the speed
// column, and measure the synthesized speed inside the outages against the logged speed.
//
// Outages: 60 s long, the first 120 s after the log starts, then one every 180 s. Methods compared:
//   (a) hold the last GPS speed;
//   (b) the paper's method (Table 2 ratios 1.25,1.35,1.50,1.7) with the gear at the outage start kept;
//   (c) the gear chosen with hindsight (theta x freq closest to the truth, or standing), auto model: a floor;
//   (d) gearpulse's SpeedSynthesizer with the auto model, causal, as the daemon runs it.
// Then (c) and (d) over the samples where the car moves, the share of (d) off by more than 8 km/h by time
// since GPS was lost, what the synthesis did in the samples it got wrong (its gear against the hindsight
// gear) and what began each run of samples in a wrong gear (an upshift or downshift the synthesis missed, a
// shift it made that the car did not, the clutch or a stop, or a gear wrong since GPS was lost), how often
// its most probable mode is the hindsight gear by the probability it gives that mode, how many upshifts
// between two samples show less than half of their ratio's drop of revs, and how many downshifts keep the
// revs level (braking while shifting down), against the level steps that stay in gear.
// Usage: bench_real_logs [DATA_DIR] [--trace FILE]   (default: the shared/data/real beside the source tree;
// --trace writes every outage sample with the truth, the hindsight gear and the synthesis as CSV)
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "bench/outage_protocol.hpp"
#include "core/estimator.hpp"
#include "core/sample_io.hpp"
#include "core/speed_synth.hpp"

namespace fs = std::filesystem;
using gearpulse::GearModel;
using gearpulse::Sample;

using namespace gearpulse::bench;  // the shared outage protocol

namespace {

struct Log {
  std::string name;
  std::vector<Sample> samples;
  std::vector<Sample> wheel;  // a Torque export's OBD wheel speed beside its GPS speed, as `gearpulse fit`
};

std::vector<Log> read_logs(const fs::path& dir, const std::string& prefix) {
  std::vector<Log> logs;
  for (const auto& p : csv_logs(dir, prefix)) {
    std::ifstream in(p, std::ios::binary);
    const gearpulse::SampleLog log = gearpulse::read_samples(in, p.string());
    logs.push_back({p.filename().string(), log.samples, {}});
    std::ifstream again(p, std::ios::binary);
    if (auto wheel = gearpulse::read_wheel_speed(again, log)) logs.back().wheel = std::move(wheel->samples);
  }
  return logs;
}

// What the synthesis did in one outage sample, against the choice made with hindsight.
enum class Kind : std::uint8_t {
  kHindsightOff,
  kAtRest,
  kCoasting,
  kOneLow,
  kLower,
  kOneHigh,
  kHigher,
  kRight
};
constexpr std::array<const char*, 8> kKindNames = {"hindsight off too", "car at rest",  "coasting, no gear",
                                                   "one gear low",      "2+ gears low", "one gear high",
                                                   "2+ gears high",     "right gear"};
// What began a run of outage samples in a wrong gear: the step from the last sample whose gear the
// synthesis and hindsight agreed on (or the start of the outage, if they never did).
enum class Origin : std::uint8_t {
  kNone,
  kFromStart,
  kMissedUpshift,
  kMissedDownshift,
  kFalseDownshift,
  kFalseUpshift,
  kClutchOrRest,
  kOther
};
constexpr std::array<const char*, 8> kOriginNames = {"",
                                                     "wrong since GPS was lost",
                                                     "upshift missed",
                                                     "downshift missed",
                                                     "false downshift",
                                                     "false upshift",
                                                     "through the clutch or a stop",
                                                     "other"};
Origin origin_of(int prev_hindsight, int prev_synth, int hindsight, int synth) {
  if (synth == 0 || hindsight == 0) return Origin::kClutchOrRest;
  if (synth == prev_synth && hindsight > prev_hindsight) return Origin::kMissedUpshift;
  if (synth == prev_synth && hindsight < prev_hindsight) return Origin::kMissedDownshift;
  if (hindsight == prev_hindsight && synth < prev_synth) return Origin::kFalseDownshift;
  if (hindsight == prev_hindsight && synth > prev_synth) return Origin::kFalseUpshift;
  return Origin::kOther;
}

constexpr double kBad = 8.0;  // km/h: an error this large is a wrong gear or a wrong stop, not jitter

struct Errors {
  std::vector<double> a, b, c, d;
  std::vector<bool> moving;    // per sample: the logged speed is above zero
  std::vector<double> since;   // per sample: s since GPS was lost
  std::vector<Kind> kind;      // per sample
  std::vector<Origin> origin;  // per sample: what began the run of samples in a wrong gear it is part of
  std::size_t upshifts = 0;    // hindsight gear up by one between two clean samples inside an outage
  std::size_t hidden = 0;      // of those, the revs fell by less than half of the two gears' ratio
  // Downshifts between two clean samples inside an outage, and how many of them kept the revs flat, against
  // the clean samples that stayed in the gear before with flat revs: all, and with both samples at speed.
  std::array<std::size_t, 2> downshifts{}, flat_down{}, flat_kept{};
  // Calibration of the synthesizer's belief, over moving samples on a gear line: by the probability of
  // its most probable mode (bins of 0.1), how often that mode is the hindsight gear.
  std::array<std::size_t, 10> belief{}, belief_right{};
};

Kind classify(const GearModel& model, double speed, double freq, double hindsight,
              const gearpulse::SynthOutput& o) {
  if (std::abs(hindsight - speed) * kMsToKmh > kBad) return Kind::kHindsightOff;
  if (speed <= 0.0) return Kind::kAtRest;
  if (o.gear <= 0) return Kind::kCoasting;
  const int off = o.gear - 1 - nearest_gear(model, speed, freq);
  if (off == 0) return Kind::kRight;
  if (off < 0) return off == -1 ? Kind::kOneLow : Kind::kLower;
  return off == 1 ? Kind::kOneHigh : Kind::kHigher;
}

std::FILE* g_trace = nullptr;  // --trace FILE: one row per outage sample

// Replays one log with outages; appends |error| in km/h of every sample inside an outage.
void replay(const std::vector<Sample>& samples, const GearModel& paper, const GearModel& model, Errors& err) {
  if (samples.empty()) return;
  gearpulse::SpeedSynthesizer synth(std::make_shared<const GearModel>(model));
  const double t0 = samples.front().t;
  double last_gps = 0.0, hold_b = 0.0, hold_c = 0.0;
  int paper_gear = -1;
  bool was_out = false;
  int clean_gear = -1;  // hindsight gear of the last outage sample on its gear line (-1: none)
  // The gears (1-based, 0 = none) of the last outage sample, hindsight's and the synthesis', whether they
  // agreed and whether they ever did in this outage, and what began the current run of disagreement.
  int prev_hindsight = 0, prev_synth = 0;
  bool prev_agreed = false, agreed_once = false;
  Origin run_origin = Origin::kNone;
  double clean_freq = 0.0, clean_speed = 0.0;
  gearpulse::LogReplayer replayer(synth);
  for (const Sample& s : samples) {
    const bool out = in_outage(s.t - t0);
    const double gps = out ? gearpulse::kMissing : s.speed;
    // As `gearpulse replay` does: a sample whose speed the outage took and whose rpm is held brings nothing.
    const gearpulse::SynthOutput o = replayer.step({s.t, gps, s.freq});
    if (!out) {
      if (s.has_speed()) last_gps = s.speed;
      if (s.has_speed() && s.has_freq())
        paper_gear = s.speed > 0.5 ? nearest_gear(paper, s.speed, s.freq) : -1;
      was_out = false;
      continue;
    }
    if (!was_out) {
      hold_b = hold_c = last_gps;
      clean_gear = -1;
      prev_agreed = agreed_once = false;
      run_origin = Origin::kNone;
    }
    was_out = true;
    if (!s.has_speed()) continue;  // no truth to compare with
    if (s.has_freq() && paper_gear >= 0 && !paper.gears.empty())
      hold_b = paper.gears[static_cast<std::size_t>(paper_gear)].theta * s.freq;
    else if (paper_gear < 0)
      hold_b = last_gps;
    // The gear whose line is nearest the sample, 1-based (0: no frequency or no ladder).
    const int nearest = s.has_freq() && !model.gears.empty() ? nearest_gear(model, s.speed, s.freq) + 1 : 0;
    if (nearest > 0) {
      hold_c = hindsight_speed(model, s.speed, s.freq);
      // A shift between two samples on their gear lines: how much of the ratio's drop of revs an upshift
      // shows, and whether a downshift keeps the revs level.
      constexpr double kOnLine = 3.0 / kMsToKmh;    // m/s
      constexpr double kFlatRevs = 0.05;            // |ln| of the revs from one clean sample to the next
      constexpr double kAtSpeed = 30.0 / kMsToKmh;  // m/s: out of town, where a driver seldom shifts down
      const int g = nearest - 1;
      const double theta = model.gears[static_cast<std::size_t>(g)].theta;
      const bool clean = s.speed > 0.0 && std::abs(theta * s.freq - s.speed) <= kOnLine;
      if (clean && clean_gear >= 0 && g == clean_gear + 1) {
        ++err.upshifts;
        const double ratio = theta / model.gears[static_cast<std::size_t>(clean_gear)].theta;
        err.hidden += std::log(clean_freq / s.freq) < 0.5 * std::log(ratio);
      }
      if (clean && clean_gear >= 0) {
        const bool flat = std::abs(std::log(s.freq / clean_freq)) < kFlatRevs;
        for (std::size_t k = 0; k < 2; ++k) {
          if (k == 1 && std::min(s.speed, clean_speed) <= kAtSpeed) continue;
          err.downshifts[k] += g == clean_gear - 1;
          err.flat_down[k] += flat && g == clean_gear - 1;
          err.flat_kept[k] += flat && g == clean_gear;
        }
      }
      clean_gear = clean ? g : -1;
      clean_freq = s.freq;
      clean_speed = s.speed;
      if (clean) {
        int top = 0;
        for (int k = 1; k <= static_cast<int>(model.gears.size()); ++k)
          if (synth.mode_probability(k) > synth.mode_probability(top)) top = k;
        const auto bin =
            std::min<std::size_t>(static_cast<std::size_t>(synth.mode_probability(top) * 10.0), 9);
        ++err.belief[bin];
        err.belief_right[bin] += top == g + 1;
      }
    }
    err.a.push_back(std::abs(last_gps - s.speed) * kMsToKmh);
    err.b.push_back(std::abs(hold_b - s.speed) * kMsToKmh);
    err.c.push_back(std::abs(hold_c - s.speed) * kMsToKmh);
    err.d.push_back(std::abs(o.speed - s.speed) * kMsToKmh);
    err.moving.push_back(s.speed > 0.0);
    err.kind.push_back(s.has_freq() && !model.gears.empty() ? classify(model, s.speed, s.freq, hold_c, o)
                                                            : Kind::kHindsightOff);
    err.since.push_back(std::fmod(s.t - t0 - kOutageStart, kOutagePeriod));
    const int hindsight_gear = s.speed > 0.0 ? nearest : 0;
    const bool agreed = hindsight_gear > 0 && o.gear == hindsight_gear;
    if (agreed)
      run_origin = Origin::kNone;
    else if (prev_agreed)
      run_origin = origin_of(prev_hindsight, prev_synth, hindsight_gear, o.gear);
    else if (!agreed_once)
      run_origin = Origin::kFromStart;
    err.origin.push_back(run_origin);
    prev_hindsight = hindsight_gear;
    prev_synth = o.gear;
    prev_agreed = agreed;
    agreed_once = agreed_once || agreed;
    if (g_trace != nullptr)
      std::fprintf(g_trace, "%.1f,%.2f,%.2f,%d,%d,%.2f,%.2f\n", s.t, s.speed * kMsToKmh, s.freq, nearest,
                   o.gear, o.speed * kMsToKmh, hold_c * kMsToKmh);
  }
}

std::vector<Sample> pool(const std::vector<Log>& logs) {
  std::vector<Sample> all;
  for (const Log& l : logs)
    all.insert(all.end(), l.samples.begin(), l.samples.end());
  return all;
}

struct Fold {
  GearModel paper, model;
};

// The paper's method on the GPS speed; gearpulse's as `gearpulse fit` does it (with the wheel speed's
// ladder where every training log also has one).
Fold fit_both(const std::vector<Log>& train) {
  gearpulse::FitOptions paper_opt;
  paper_opt.ratios = {1.25, 1.35, 1.50, 1.7};  // Table 2, c1..c4 (top gear down)
  const std::vector<Sample> gps = pool(train);
  std::vector<gearpulse::TwoSpeedLog> both;
  for (const Log& l : train)
    if (!l.wheel.empty()) both.push_back({l.samples, l.wheel});
  const GearModel model = both.size() == train.size() && !both.empty()
                              ? gearpulse::fit_gear_model_two_speeds(both, {}).model
                              : gearpulse::fit_gear_model(gps, {}).model;
  return {gearpulse::fit_gear_model(gps, paper_opt).model, model};
}

std::string thetas(const GearModel& m) {
  std::string s;
  char buf[32];
  for (const auto& g : m.gears) {
    std::snprintf(buf, sizeof buf, "%s%.4f", s.empty() ? "" : ",", g.theta);
    s += buf;
  }
  return s.empty() ? "(none)" : s;
}

void report(const char* title, const Errors& e) {
  std::printf("%s: %zu samples inside outages, |error| km/h median / p95\n", title, e.d.size());
  std::printf("  (a) hold last GPS speed        %6.2f / %6.2f\n", quantile(e.a, 0.5), quantile(e.a, 0.95));
  std::printf("  (b) paper thetas, gear kept    %6.2f / %6.2f\n", quantile(e.b, 0.5), quantile(e.b, 0.95));
  std::printf("  (c) auto thetas, hindsight gear%6.2f / %6.2f\n", quantile(e.c, 0.5), quantile(e.c, 0.95));
  std::printf("  (d) gearpulse synthesis        %6.2f / %6.2f\n", quantile(e.d, 0.5), quantile(e.d, 0.95));
  // The same over the samples where the car moves (a car at rest has no gear to choose with hindsight).
  std::vector<double> c_moving, d_moving;
  for (std::size_t k = 0; k < e.d.size(); ++k) {
    if (!e.moving[k]) continue;
    c_moving.push_back(e.c[k]);
    d_moving.push_back(e.d[k]);
  }
  std::printf("  moving samples only (%zu): (c) %.2f / %.2f, (d) %.2f / %.2f\n", d_moving.size(),
              quantile(c_moving, 0.5), quantile(c_moving, 0.95), quantile(d_moving, 0.5),
              quantile(d_moving, 0.95));
  // How the synthesis fares with the time since GPS was lost: share of samples off by more than 8 km/h.
  constexpr double kBin = 10.0;  // s
  std::printf("  (d) share off by more than %.0f km/h, by s since GPS was lost:", kBad);
  for (double from = 0.0; from < kOutageLength; from += kBin) {
    std::size_t n = 0, bad = 0;
    for (std::size_t k = 0; k < e.d.size(); ++k) {
      if (e.since[k] < from || e.since[k] >= from + kBin) continue;
      ++n;
      bad += e.d[k] > kBad;
    }
    std::printf(" %.0f-%.0f %.0f %%", from, from + kBin,
                n ? 100.0 * static_cast<double>(bad) / static_cast<double>(n) : 0.0);
  }
  std::printf("\n");
  // Where those errors come from, as shares of all outage samples.
  std::array<std::size_t, kKindNames.size()> kinds{};
  std::size_t bad = 0;
  for (std::size_t k = 0; k < e.d.size(); ++k) {
    if (e.d[k] <= kBad) continue;
    ++bad;
    ++kinds[static_cast<std::size_t>(e.kind[k])];
  }
  const auto share = [&](std::size_t n) {
    return 100.0 * static_cast<double>(n) / static_cast<double>(e.d.size());
  };
  std::printf("  (d) off by more than %.0f km/h: %.1f %% of samples:", kBad, share(bad));
  const char* sep = "";
  for (std::size_t k = 0; k < kinds.size(); ++k) {
    if (kinds[k] == 0) continue;
    std::printf("%s %s %.1f %%", sep, kKindNames[k], share(kinds[k]));
    sep = ",";
  }
  std::printf("\n");
  // The samples in a wrong gear among them, by the step that began their run of disagreement.
  std::array<std::size_t, kOriginNames.size()> origins{};
  for (std::size_t k = 0; k < e.d.size(); ++k)
    if (e.d[k] > kBad && e.kind[k] >= Kind::kOneLow && e.kind[k] <= Kind::kHigher)
      ++origins[static_cast<std::size_t>(e.origin[k])];
  std::printf("  (d) of those in a wrong gear, by what began the run:");
  sep = "";
  for (std::size_t k = 1; k < origins.size(); ++k) {
    if (origins[k] == 0) continue;
    std::printf("%s %s %.1f %%", sep, kOriginNames[k], share(origins[k]));
    sep = ",";
  }
  std::printf("\n");
  std::printf("  calibration: the synthesis' most probable mode is the hindsight gear, by its probability:");
  for (std::size_t b = 0; b < e.belief.size(); ++b)
    if (e.belief[b] >= 20)
      std::printf(" %.1f-%.1f %.0f %% (%zu)", 0.1 * static_cast<double>(b), 0.1 * static_cast<double>(b + 1),
                  100.0 * static_cast<double>(e.belief_right[b]) / static_cast<double>(e.belief[b]),
                  e.belief[b]);
  std::printf("\n");
  if (e.upshifts > 0)
    std::printf(
        "  upshifts between two samples on their gear lines: %zu; the revs fell by less than half of the "
        "ratio in %.0f %%\n",
        e.upshifts, 100.0 * static_cast<double>(e.hidden) / static_cast<double>(e.upshifts));
  const auto pct = [](std::size_t part, std::size_t whole) {
    return whole > 0 ? 100.0 * static_cast<double>(part) / static_cast<double>(whole) : 0.0;
  };
  for (std::size_t k = 0; k < 2; ++k)
    if (e.downshifts[k] > 0)
      std::printf(
          "  downshifts between two samples on their gear lines%s: %zu, %.0f %% with the revs within 5 %%; "
          "of the steps with revs so flat, %.1f %% are a downshift (%zu stayed in gear)\n",
          k == 0 ? "" : ", both above 30 km/h", e.downshifts[k], pct(e.flat_down[k], e.downshifts[k]),
          pct(e.flat_down[k], e.flat_down[k] + e.flat_kept[k]), e.flat_kept[k]);
}

// Fit on `train`, replay every log of `test`.
void run_fold(const char* label, const std::vector<Log>& train, const std::vector<Log>& test, Errors& e) {
  const Fold f = fit_both(train);
  std::printf("  fold %-28s paper theta %s\n", label, thetas(f.paper).c_str());
  std::printf("  %-33s auto  theta %s\n", "", thetas(f.model).c_str());
  if (const auto line = f.model.extra.find("speed_scale"); line != f.model.extra.end())
    std::printf("  %-33s (wheel speed onto GPS: %.4f x %+.3f m/s over %zu rows)\n", "",
                line->value("slope", 1.0), line->value("offset", 0.0), line->value("pairs", std::size_t{0}));
  for (const Log& l : test) {
    if (g_trace != nullptr) std::fprintf(g_trace, "# %s\n", l.name.c_str());
    replay(l.samples, f.paper, f.model, e);
  }
}

}  // namespace

// How far above its standing idle an engine runs while the car rolls declutched: over runs of three
// readings with flat revs (within 6 %) while the car, above 3 m/s, slows by more than 1 m/s, the revs
// against that log's standing idle (the median at speed 0). The upper quartile holds shifts caught between
// readings.
void print_rolling_revs(const char* title, const std::vector<Log>& logs) {
  std::vector<double> ratios;
  for (const Log& log : logs) {
    std::vector<double> standing;
    for (const Sample& s : log.samples)
      if (s.has_speed() && s.has_freq() && s.speed == 0.0 && s.freq > 0.0) standing.push_back(s.freq);
    if (standing.empty()) continue;
    const double idle = quantile(standing, 0.5);
    const std::vector<Sample>& x = log.samples;
    for (std::size_t i = 0; i + 2 < x.size(); ++i) {
      bool usable = true;
      double lo = 0.0, hi = 0.0, slowest = 0.0;
      for (std::size_t k = i; k < i + 3; ++k) {
        usable = usable && x[k].has_speed() && x[k].has_freq() && x[k].freq > 0.0;
        if (!usable) break;
        lo = k == i ? x[k].freq : std::min(lo, x[k].freq);
        hi = k == i ? x[k].freq : std::max(hi, x[k].freq);
        slowest = k == i ? x[k].speed : std::min(slowest, x[k].speed);
      }
      if (usable && slowest >= 3.0 && hi <= 1.06 * lo && x[i + 2].speed < x[i].speed - 1.0)
        ratios.push_back(x[i + 1].freq / idle);
    }
  }
  if (ratios.empty()) return;
  std::printf(
      "%s: rolling declutched, %zu runs of three readings with flat revs while slowing above 3 m/s: revs / "
      "standing idle quartiles %.2f / %.2f / %.2f\n",
      title, ratios.size(), quantile(ratios, 0.25), quantile(ratios, 0.5), quantile(ratios, 0.75));
}

int main(int argc, char** argv) {
  fs::path root = GEARPULSE_REAL_DATA_DIR;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> trace(nullptr, &std::fclose);
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--trace" && i + 1 < argc) {
      trace.reset(std::fopen(argv[++i], "w"));
      if (!trace) {
        std::fprintf(stderr, "bench_real_logs: cannot write %s\n", argv[i]);
        return 1;
      }
      g_trace = trace.get();
      std::fprintf(g_trace, "t,speed_kmh,freq_hz,best_gear,synth_gear,synth_kmh,hindsight_kmh\n");
    } else {
      root = arg;
    }
  }
  const auto start = std::chrono::steady_clock::now();

  const fs::path etios = root / "carloop-etios";
  const std::vector<Log> drives = read_logs(etios, "drive");
  const std::vector<Log> longs = read_logs(etios, "long");
  if (!drives.empty() && !longs.empty()) {
    Errors e;
    std::printf("Etios (Carloop OBD, ~1.8 s refresh): two folds, fit on one set, replay the other\n");
    run_fold("fit drive*, replay long*", drives, longs, e);
    run_fold("fit long*, replay drive*", longs, drives, e);
    report("Etios", e);
    std::vector<Log> all = drives;
    all.insert(all.end(), longs.begin(), longs.end());
    print_rolling_revs("Etios", all);
  } else {
    std::printf("Etios logs not found under %s\n", etios.c_str());
  }

  const std::vector<Log> louis = read_logs(root / "torque-louisville", "");
  if (!louis.empty()) {
    const std::vector<Sample>& all = louis.front().samples;
    const std::size_t half = all.size() / 2;
    const double split = all[half].t;
    std::vector<Sample> wheel_first, wheel_second;
    for (const Sample& w : louis.front().wheel)
      (w.t < split ? wheel_first : wheel_second).push_back(w);
    const std::vector<Log> first = {
        {"first half", {all.begin(), all.begin() + static_cast<long>(half)}, wheel_first}};
    const std::vector<Log> second = {
        {"second half", {all.begin() + static_cast<long>(half), all.end()}, wheel_second}};
    Errors e;
    std::printf(
        "\nLouisville (Torque, 1 Hz GPS speed; gearpulse's ladder from the OBD wheel speed, scaled to "
        "GPS): cross-validation halves\n");
    run_fold("fit 1st half, replay 2nd", first, second, e);
    run_fold("fit 2nd half, replay 1st", second, first, e);
    report("Louisville", e);
  }
  // The Swift's `speed,rpm` log has no time column: the reader takes the row counter as time, and how far
  // apart its rows were is not known. Replayed at 1 s per row (as `gearpulse replay` reads it) and at 2.
  const std::vector<Log> swift = read_logs(root / "swift-147", "");
  for (const double row_s : {1.0, 2.0}) {
    if (swift.empty()) break;
    std::vector<Sample> all = swift.front().samples;
    for (Sample& x : all)
      x.t *= row_s;
    const std::size_t half = all.size() / 2;
    const std::vector<Log> first = {{"first half", {all.begin(), all.begin() + static_cast<long>(half)}, {}}};
    const std::vector<Log> second = {{"second half", {all.begin() + static_cast<long>(half), all.end()}, {}}};
    Errors e;
    std::printf(
        "\nSwift (speed,rpm rows without a time column, integer km/h wheel speed; %.0f s per row): "
        "cross-validation halves\n",
        row_s);
    run_fold("fit 1st half, replay 2nd", first, second, e);
    run_fold("fit 2nd half, replay 1st", second, first, e);
    report(row_s == 1.0 ? "Swift, 1 s per row" : "Swift, 2 s per row", e);
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("\n(%.1f s)\n", secs);
  return 0;
}
