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

// ---- Short clips started cold (--clips) ----

// A clip's content, from its truth: a launch or pull (the line rising faster than 20 Hz/s over 0.5 s, as a
// launch's first gears at 10-50 Hz/s), the engine in the band otherwise (cruise, coast, a shift alone), or
// idle only (no hop in the band).
enum ClipKind { kLaunch, kCruise, kIdleOnly, kClipKinds };
constexpr const char* kClipKindNames[kClipKinds] = {"launch/pull", "cruise/coast", "idle only"};

ClipKind clip_kind(const sim::FrequencyTrajectory& truth, double from, double to) {
  constexpr double kStepS = 0.1, kSpanS = 0.5, kRiseHzPerS = 20.0;
  bool any = false;
  for (double t = from; t < to; t += kStepS) {
    const double a = truth(t);
    if (!(a >= kScoredLoHz && a <= kScoredHiHz)) continue;
    any = true;
    if (a - truth(t - kSpanS) > kRiseHzPerS * kSpanS) return kLaunch;
  }
  return any ? kCruise : kIdleOnly;
}

// The clips' hops scored as the scene's (in the band and at idle) beside the same hops of the whole-scene
// run, by content; and the time from a clip's start to its first right tracked hop, for clips that start
// with the engine in the band.
struct ClipScores {
  OrderScore clip[kClipKinds], whole[kClipKinds], clip_idle, whole_idle;
  double first_sum[2] = {};
  std::size_t first_n[2] = {}, never[2] = {};
  explicit ClipScores(double hop_s) {
    for (int k = 0; k < kClipKinds; ++k) {
      clip[k].band_lo = whole[k].band_lo = kScoredLoHz;
      clip[k].band_hi = whole[k].band_hi = kScoredHiHz;
      clip[k].hop_s = whole[k].hop_s = hop_s;
    }
    for (OrderScore* s : {&clip_idle, &whole_idle}) {
      s->band_lo = kIdleLoHz;
      s->band_hi = kScoredLoHz;
      s->hop_s = hop_s;
    }
  }
  void first_right(int which, double from, double at) {
    if (std::isfinite(at)) {
      first_sum[which] += at - from;
      ++first_n[which];
    } else {
      ++never[which];
    }
  }
  static void line(const char* label, OrderScore s) {
    s.close_run();
    double other = 0.0;
    for (const std::size_t n : s.at_order)
      other += Score::pct(n, s.tracked);
    std::printf(
        "%s coverage %5.1f %% of %5zu, gross %5.2f %% (%5.2f %% at another order), %zu locks > %.1f s\n",
        label, Score::pct(s.tracked, s.in_band), s.in_band, Score::pct(s.gross, s.tracked),
        s.tracked ? other : NAN, s.long_locks, kLockLimitS);
  }
  void print(double clip_s) const {
    for (int k = 0; k < kClipKinds; ++k) {
      if (clip[k].in_band == 0) continue;
      std::printf("      %-12s", kClipKindNames[k]);
      line(" clips", clip[k]);
      std::printf("      %-12s", "");
      line(" whole", whole[k]);
    }
    std::printf(
        "      idle (%g-%g Hz) right/wrong: clips %5.1f / %4.1f %%, whole %5.1f / %4.1f %% of %zu hops\n",
        kIdleLoHz, kScoredLoHz, Score::pct(clip_idle.right_n, clip_idle.in_band),
        Score::pct(clip_idle.gross, clip_idle.in_band), Score::pct(whole_idle.right_n, whole_idle.in_band),
        Score::pct(whole_idle.gross, whole_idle.in_band), whole_idle.in_band);
    std::printf(
        "      first right tracked hop after a %g s clip's start in the band: clips %.2f s (%zu never), "
        "whole %.2f s (%zu never) of %zu clips\n",
        clip_s, first_n[0] ? first_sum[0] / static_cast<double>(first_n[0]) : NAN, never[0],
        first_n[1] ? first_sum[1] / static_cast<double>(first_n[1]) : NAN, never[1], first_n[0] + never[0]);
  }
};

// Cuts the scene `x` into consecutive clips of clip_s, runs a fresh tracker on each from its start and
// scores its hops beside the same hops of the whole-scene run `whole` (keyed by hop index).
void score_clips(const std::vector<float>& x, const sim::FrequencyTrajectory& truth, const TrackerConfig& tc,
                 double clip_s, const std::vector<TrackPoint>& whole, ClipScores& out,
                 const std::string& label) {
  const auto clip_frames = static_cast<std::size_t>(std::llround(clip_s * tc.sample_rate_hz));
  const auto hop_index = [&](double t) { return std::llround(t / tc.hop_s); };
  std::vector<const TrackPoint*> by_hop;
  for (const TrackPoint& p : whole) {
    const auto i = static_cast<std::size_t>(std::max(0LL, hop_index(p.t)));
    if (by_hop.size() <= i) by_hop.resize(i + 1, nullptr);
    by_hop[i] = &p;
  }
  SlidingDftTracker tracker(tc);
  const bool dump = std::getenv("GEARPULSE_BENCH_DUMP") != nullptr;
  for (std::size_t from = 0; from + clip_frames <= x.size(); from += clip_frames) {
    const double t0 = static_cast<double>(from) / tc.sample_rate_hz;
    const ClipKind kind = clip_kind(truth, t0, t0 + clip_s);
    const bool starts_in_band = truth(t0) >= kScoredLoHz && truth(t0) <= kScoredHiHz;
    double first[2] = {NAN, NAN};
    tracker.start(t0);
    char tag[96];
    std::snprintf(tag, sizeof tag, "%s clip %.0f s %s", label.c_str(), t0, kClipKindNames[kind]);
    out.clip[kind].tag = tag;
    out.whole[kind].tag = std::string(tag) + " (whole run)";
    out.clip_idle.tag = std::string(tag) + " idle";
    out.whole_idle.tag = std::string(tag) + " idle (whole run)";
    run_tracker(tracker, std::span<const float>(x).subspan(from, clip_frames), [&](const TrackPoint& p) {
      const auto i = static_cast<std::size_t>(std::max(0LL, hop_index(p.t)));
      if (i >= by_hop.size() || by_hop[i] == nullptr) return;
      const TrackPoint& w = *by_hop[i];
      const double f = truth(p.t);
      if (dump)
        std::printf("clip %s %.2f %.2f %.2f %.1f %d %.3f\n", label.c_str(), p.t, f, p.freq, p.snr_db,
                    p.tracked, p.confidence);
      out.clip[kind].add(p, f);
      out.whole[kind].add(w, f);
      out.clip_idle.add(p, f);
      out.whole_idle.add(w, f);
      const bool in = f >= kScoredLoHz && f <= kScoredHiHz;
      if (in && p.tracked && right(p.freq, f) && !std::isfinite(first[0])) first[0] = p.t;
      if (in && w.tracked && right(w.freq, f) && !std::isfinite(first[1])) first[1] = w.t;
    });
    out.clip[kind].close_run();  // a lock on another order ends with its clip
    out.whole[kind].close_run();
    out.clip_idle.close_run();
    out.whole_idle.close_run();
    if (starts_in_band)
      for (int which : {0, 1})
        out.first_right(which, t0, first[which]);
  }
}

}  // namespace

int scenes(const std::string& set, const TrackerConfig& base, const std::vector<std::string>& without,
           const std::vector<double>& snrs, double clip_s) {
  const bool run_up = set.starts_with("runup"), no_third = set.starts_with("no-third");
  constexpr double kDurationS = 120.0;
  const bool tuning_seeds = set == "tuning" || set == "runup" || set == "no-third";
  const std::uint64_t first = tuning_seeds ? 101 : set == "check" ? 301 : 201;
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
        "scenes (%s set: seeds %llu-%llu, %.0f s each at 48 kHz, launch drives of a four-cylinder%s), "
        "band %g:%g Hz, window %g s, hop %g s\n",
        set.c_str(), static_cast<unsigned long long>(first),
        static_cast<unsigned long long>(first + kSeeds - 1), kDurationS,
        no_third ? "; orders 1, 2 and 4, no 3rd harmonic; the half orders in the odd seeds only" : "",
        base.band_lo_hz, base.band_hi_hz, base.window_s, base.hop_s);
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
    ClipScores clips(base.hop_s);
    for (int i = 0; i < kSeeds; ++i) {
      const std::uint64_t seed = first + static_cast<std::uint64_t>(i);
      const double duration = run_up ? sim::run_up_duration(run_up_ramp_s(i)) : kDurationS;
      const auto trajectory =
          run_up ? sim::run_up_trajectory(run_up_ramp_s(i)) : sim::launch_drive_trajectory(duration, seed);
      sim::LighterSceneConfig cfg = run_up     ? sim::run_up_scene_for_seed(seed, snr, run_up_ramp_s(i))
                                    : no_third ? sim::no_third_scene_for_seed(seed, snr, seed % 2 == 1)
                                               : sim::scene_for_seed(seed, snr);
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
      char label[64];
      std::snprintf(label, sizeof label, "  seed %3llu %5.1f dB", static_cast<unsigned long long>(seed), snr);
      s.tag = label;
      idle.tag = std::string(label) + " idle";
      const bool dump = std::getenv("GEARPULSE_BENCH_DUMP") != nullptr;
      std::vector<TrackPoint> hops;
      spent += run_tracker(tracker, x, [&](const TrackPoint& p) {
        if (dump)
          std::printf("%llu %.2f %.2f %.2f %.1f %d %.3f\n", static_cast<unsigned long long>(seed), p.t,
                      trajectory(p.t), p.freq, p.snr_db, p.tracked, p.confidence);
        s.add(p, trajectory(p.t));
        idle.add(p, trajectory(p.t));
        split.add(p, trajectory(p.t), after_shift_or_entry(trajectory, p.t));
        if (clip_s > 0.0) hops.push_back(p);
      });
      if (clip_s > 0.0) score_clips(x, trajectory, tc, clip_s, hops, clips, label);
      audio += duration;
      s.close_run();  // the scene's lock ends with it: printed once, here
      s.print(label);
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
    if (clip_s > 0.0) {
      std::printf("    clips of %g s started cold, beside the same hops of the whole scenes:\n", clip_s);
      clips.print(clip_s);
    }
  }
  std::printf("CPU: %.2f s for %.0f s of 48 kHz audio (%.3f %% of one core)\n", spent, audio,
              100.0 * spent / audio);
  return 0;
}

}  // namespace gearpulse::bench::tracker_bench
