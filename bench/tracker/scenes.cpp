#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench/tracker/tracker.hpp"
#include "tools/sim/lighter_signal_scene.hpp"

namespace gearpulse::bench::tracker_bench {
namespace {

// The scenes are scored in two parts whatever the tracker's band: the engine above idle (50-200 Hz, the
// band the targets are stated on, "in-band hops") and the idle below it (20-50 Hz: the scenes idle at
// 25-30 Hz), where a hop tracked within 5 % is right and any other tracked hop is wrong.
constexpr double kScoredLoHz = 50.0, kScoredHiHz = 200.0, kIdleLoHz = 20.0;

// Whether the hop at t lies within 2 s of a gear shift (the truth moving faster than 60 Hz/s over 0.2 s:
// a shift, a rev blip) or of the line's entry into the band.
bool after_shift_or_entry(const sim::FrequencyTrajectory& truth, double t) {
  constexpr double kWithinS = 2.0, kStepS = 0.05, kSpanS = 0.2, kShiftHzPerS = 60.0;
  for (double s = 0.0; s <= kWithinS + 1e-9; s += kStepS) {
    const double a = truth(t - s), b = truth(t - s - kSpanS);
    if (!(a >= kScoredLoHz && a <= kScoredHiHz)) return true;
    if (!std::isfinite(b) || std::abs(a - b) > kShiftHzPerS * kSpanS) return true;
  }
  return false;
}

// In-band hops tracked right within 2 s of a shift or entry, and later.
struct ShiftSplit {
  std::size_t hops[2] = {}, right_n[2] = {};
  void add(const TrackPoint& p, double truth, bool after_shift) {
    if (!(std::isfinite(truth) && truth >= kScoredLoHz && truth <= kScoredHiHz)) return;
    ++hops[after_shift];
    right_n[after_shift] += p.tracked && right(p.freq, truth);
  }
  void print() const {
    const std::size_t all = hops[0] + hops[1];
    std::printf(
        "      tracked right (points of coverage lost): within 2 s of a shift or entry %5.1f %% of %zu"
        " (%4.1f), later %5.1f %% of %zu (%4.1f)\n",
        Score::pct(right_n[1], hops[1]), hops[1], Score::pct(hops[1] - right_n[1], all),
        Score::pct(right_n[0], hops[0]), hops[0], Score::pct(hops[0] - right_n[0], all));
  }
};

// The run-up set: the scenes of the tuning seeds' levels and other lines, driven by a run-up at full throttle
// (970 -> 4,820 rpm over 10, 12, ... 20 s) whose 2nd harmonic stands 6 dB over the fundamental at 2,400 rpm
// (sim::run_up_scene_for_seed()), where a real cabin run-up can be held at twice the engine.
double run_up_ramp_s(int i) {
  return 10.0 + 2.0 * i;
}

}  // namespace

int scenes(const std::string& set, const TrackerConfig& base, const std::vector<std::string>& without,
           const std::vector<double>& snrs) {
  const bool run_up = set.starts_with("runup");
  constexpr double kDurationS = 120.0;
  const std::uint64_t first = set == "tuning" || set == "runup" ? 101 : set == "check" ? 301 : 201;
  constexpr int kSeeds = 6;
  if (run_up)
    std::printf(
        "scenes (%s set: the levels of seeds %llu-%llu, run-ups of a four-cylinder at full throttle, "
        "970 -> 4,820 rpm over 10-20 s, the 2nd harmonic 6 dB over the fundamental at 80 Hz), band %g:%g Hz, "
        "window %g s, hop %g s\n",
        set.c_str(), static_cast<unsigned long long>(first),
        static_cast<unsigned long long>(first + kSeeds - 1), base.band_lo_hz, base.band_hi_hz, base.window_s,
        base.hop_s);
  else
    std::printf(
        "scenes (%s set: seeds %llu-%llu, %.0f s each at 48 kHz, launch drives of a four-cylinder), "
        "band %g:%g Hz, window %g s, hop %g s\n",
        set.c_str(), static_cast<unsigned long long>(first),
        static_cast<unsigned long long>(first + kSeeds - 1), kDurationS, base.band_lo_hz, base.band_hi_hz,
        base.window_s, base.hop_s);
  if (base.decision_lag_s > 0.0) std::printf("decision lag %g s\n", base.decision_lag_s);
  if (!without.empty()) {
    std::printf("without:");
    for (const std::string& w : without)
      std::printf(" %s", w.c_str());
    std::printf("\n");
  }
  double spent = 0.0, audio = 0.0;
  for (const double snr : snrs) {
    OrderScore pooled, pooled_idle;
    ShiftSplit split;
    for (int i = 0; i < kSeeds; ++i) {
      const std::uint64_t seed = first + static_cast<std::uint64_t>(i);
      const double duration = run_up ? sim::run_up_duration(run_up_ramp_s(i)) : kDurationS;
      const auto trajectory =
          run_up ? sim::run_up_trajectory(run_up_ramp_s(i)) : sim::launch_drive_trajectory(duration, seed);
      sim::LighterSceneConfig cfg =
          run_up ? sim::run_up_scene_for_seed(seed, snr, run_up_ramp_s(i)) : sim::scene_for_seed(seed, snr);
      // The automatic gain last: its fixed stand-in holds the envelope of the components left on.
      for (const bool gain : {false, true})
        for (const std::string& w : without)
          if ((w == "agc") == gain && !sim::scene_without(cfg, w, trajectory, duration))
            throw std::runtime_error("--scene-without: no component " + w);
      const std::vector<float> x = sim::make_lighter_scene(cfg, trajectory, duration);
      TrackerConfig tc = base;
      SlidingDftTracker tracker(tc);
      OrderScore s, idle;
      s.band_lo = kScoredLoHz;
      s.band_hi = kScoredHiHz;
      s.hop_s = idle.hop_s = tc.hop_s;
      idle.band_lo = kIdleLoHz;
      idle.band_hi = kScoredLoHz;
      const bool dump = std::getenv("GEARPULSE_BENCH_DUMP") != nullptr;
      spent += run_tracker(tracker, x, [&](const TrackPoint& p) {
        if (dump)
          std::printf("%llu %.2f %.2f %.2f %.1f %d %.3f\n", static_cast<unsigned long long>(seed), p.t,
                      trajectory(p.t), p.freq, p.snr_db, p.tracked, p.confidence);
        s.add(p, trajectory(p.t));
        idle.add(p, trajectory(p.t));
        split.add(p, trajectory(p.t), after_shift_or_entry(trajectory, p.t));
      });
      audio += duration;
      char label[64];
      std::snprintf(label, sizeof label, "  seed %3llu %5.1f dB", static_cast<unsigned long long>(seed), snr);
      OrderScore shown = s;
      shown.print(label);
      pooled.merge(s);
      pooled_idle.merge(idle);
    }
    char label[64];
    std::snprintf(label, sizeof label, "pooled %5.1f dB", snr);
    pooled.print(label);
    std::printf("      idle (%g-%g Hz): %5.1f %% of %zu hops tracked right, %5.1f %% wrong\n", kIdleLoHz,
                kScoredLoHz, Score::pct(pooled_idle.right_n, pooled_idle.in_band), pooled_idle.in_band,
                Score::pct(pooled_idle.gross, pooled_idle.in_band));
    split.print();
  }
  std::printf("CPU: %.2f s for %.0f s of 48 kHz audio (%.3f %% of one core)\n", spent, audio,
              100.0 * spent / audio);
  return 0;
}

}  // namespace gearpulse::bench::tracker_bench
