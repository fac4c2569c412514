#pragma once
// The parts of the tracker bench (bench/bench_tracker.cpp holds main() and says what the bench measures and
// how it is run): the scores kept over a run's hops (here), the generated drives of the default run and the
// CPU figure (drives.cpp), the scenes over fixed seed sets (scenes.cpp) and a real recording against a tacho
// log (wav.cpp).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include "bench/requirements.hpp"
#include "core/sliding_dft_tracker.hpp"

namespace gearpulse::bench::tracker_bench {

inline double cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

inline bool in_band(double f) {
  return std::isfinite(f) && f >= 50.0 && f <= 200.0;
}

inline bool right(double est, double truth) {
  return std::isfinite(est) && std::abs(est - truth) <= 0.05 * truth;
}

// Reliability of the confidence: per bin of reported confidence, the share of in-band estimates that
// were right (within 5 %).
struct Calibration {
  static constexpr int kBins = 5;
  static constexpr double kEdge[kBins + 1] = {0.0, 0.2, 0.5, 0.8, 0.95, 1.0};
  std::size_t n[kBins] = {}, ok[kBins] = {};
  void add(double confidence, bool is_right) {
    int b = 0;
    while (b + 1 < kBins && confidence >= kEdge[b + 1])
      ++b;
    ++n[b];
    ok[b] += is_right;
  }
  void print() const {
    std::printf("      confidence -> share right:");
    for (int b = 0; b < kBins; ++b) {
      if (n[b] == 0) {
        std::printf("  [%.2f,%.2f) -", kEdge[b], kEdge[b + 1]);
        continue;
      }
      std::printf("  [%.2f,%.2f) %3.0f %% of %zu", kEdge[b], kEdge[b + 1],
                  100.0 * static_cast<double>(ok[b]) / static_cast<double>(n[b]), n[b]);
    }
    std::printf("\n");
  }
};

struct Score {
  double sq = 0.0;
  std::size_t n = 0, gross = 0, in_band = 0, false_tracks = 0, out_band = 0;
  std::size_t valued = 0, valued_gross = 0;  // in-band hops with an estimate at any confidence
  Calibration calibration;
  void add_in_band(bool tracked, double est, double truth) {
    ++in_band;
    if (!tracked) return;
    ++n;
    sq += (est - truth) * (est - truth);
    gross += !right(est, truth);
  }
  void add_in_band(const TrackPoint& p, double truth) {
    add_in_band(p.tracked, p.freq, truth);
    if (!std::isfinite(p.freq)) return;
    ++valued;
    valued_gross += !right(p.freq, truth);
    calibration.add(p.confidence, right(p.freq, truth));
  }
  // A hop whose true frequency is outside the band (engine off, idling, just below the band's edge):
  // false when it is tracked with a frequency that is not the engine's.
  void add_out_band(bool tracked, double est, double truth) {
    ++out_band;
    if (tracked && !right(est, truth)) ++false_tracks;
  }
  void merge(const Score& o) {
    sq += o.sq;
    n += o.n;
    gross += o.gross;
    in_band += o.in_band;
    false_tracks += o.false_tracks;
    out_band += o.out_band;
    valued += o.valued;
    valued_gross += o.valued_gross;
    for (int b = 0; b < Calibration::kBins; ++b) {
      calibration.n[b] += o.calibration.n[b];
      calibration.ok[b] += o.calibration.ok[b];
    }
  }
  [[nodiscard]] static double pct(std::size_t a, std::size_t b) {
    return b ? 100.0 * static_cast<double>(a) / static_cast<double>(b) : NAN;
  }
  [[nodiscard]] double rmse() const { return n ? std::sqrt(sq / static_cast<double>(n)) : NAN; }
  [[nodiscard]] double gross_pct() const { return pct(gross, n); }
  [[nodiscard]] double tracked_pct() const { return pct(n, in_band); }
  [[nodiscard]] double false_pct() const { return pct(false_tracks, out_band); }
  [[nodiscard]] double valued_pct() const { return pct(valued, in_band); }
  [[nodiscard]] double valued_gross_pct() const { return pct(valued_gross, valued); }
};

// ---- Scoring against a truth that may sit at another order of what the tracker follows ----

// Ratios of estimate to truth that are reported as "at another order".
inline constexpr double kOtherOrders[] = {1.0 / 3.0, 0.5, 2.0 / 3.0, 1.5, 2.0, 3.0, 4.0};
inline constexpr const char* kOtherOrderNames[] = {"x1/3", "x0.5", "x2/3", "x1.5", "x2", "x3", "x4"};
inline constexpr int kOtherOrderCount = static_cast<int>(std::size(kOtherOrders));
inline constexpr double kLockLimitS = 0.3;  // longest acceptable lock on another order

// Index into kOtherOrders of the order `est` sits at (within 5 %), or -1.
inline int other_order(double est, double truth) {
  for (int i = 0; i < kOtherOrderCount; ++i)
    if (right(est, kOtherOrders[i] * truth)) return i;
  return -1;
}

struct OrderScore {
  double band_lo = 50.0, band_hi = 200.0, hop_s = 0.1;
  std::size_t in_band = 0, tracked = 0, gross = 0, right_n = 0;
  double sq = 0.0;
  std::size_t at_order[kOtherOrderCount] = {};
  double longest_lock_s = 0.0;
  std::size_t long_locks = 0;  // locks on another order longer than kLockLimitS
  Calibration calibration;
  std::size_t valued = 0, valued_right = 0;
  double confidence_sum = 0.0;
  // The run of consecutive tracked hops at one other order.
  int run_order = -1;
  double run_from = 0.0, run_to = 0.0;
  // With GEARPULSE_BENCH_LOCKS set, every lock over kLockLimitS is printed with this label when its run
  // closes (close_run(), which print() and merge() call).
  std::string tag;

  void close_run() {
    if (run_order < 0) return;
    const double length = run_to - run_from + hop_s;
    longest_lock_s = std::max(longest_lock_s, length);
    long_locks += length > kLockLimitS + 1e-9;
    if (length > kLockLimitS + 1e-9 && std::getenv("GEARPULSE_BENCH_LOCKS") != nullptr)
      std::printf("lock %s %s %.1f-%.1f s, %.1f s\n", tag.c_str(), kOtherOrderNames[run_order], run_from,
                  run_to, length);
    run_order = -1;
  }
  void add(const TrackPoint& p, double truth) {
    if (!(std::isfinite(truth) && truth >= band_lo && truth <= band_hi)) {
      close_run();
      return;
    }
    ++in_band;
    if (std::isfinite(p.freq)) {
      ++valued;
      valued_right += right(p.freq, truth);
      confidence_sum += p.confidence;
      calibration.add(p.confidence, right(p.freq, truth));
    }
    const int order = p.tracked ? other_order(p.freq, truth) : -1;
    if (order != run_order) close_run();
    if (order >= 0 && run_order < 0) {
      run_order = order;
      run_from = p.t;
    }
    if (order >= 0) run_to = p.t;
    if (!p.tracked) return;
    ++tracked;
    if (right(p.freq, truth)) {
      ++right_n;
      sq += (p.freq - truth) * (p.freq - truth);
    } else {
      ++gross;
    }
    if (order >= 0) ++at_order[order];
  }
  void merge(OrderScore o) {
    close_run();
    o.close_run();
    in_band += o.in_band;
    tracked += o.tracked;
    gross += o.gross;
    right_n += o.right_n;
    sq += o.sq;
    for (int i = 0; i < kOtherOrderCount; ++i)
      at_order[i] += o.at_order[i];
    longest_lock_s = std::max(longest_lock_s, o.longest_lock_s);
    long_locks += o.long_locks;
    for (int b = 0; b < Calibration::kBins; ++b) {
      calibration.n[b] += o.calibration.n[b];
      calibration.ok[b] += o.calibration.ok[b];
    }
    valued += o.valued;
    valued_right += o.valued_right;
    confidence_sum += o.confidence_sum;
  }
  void print(const char* label) {
    close_run();
    std::printf("%s: coverage %5.1f %% of %zu in-band hops | rmse %6.3f Hz (right hops) | gross %5.2f %%",
                label, Score::pct(tracked, in_band), in_band,
                right_n ? std::sqrt(sq / static_cast<double>(right_n)) : NAN, Score::pct(gross, tracked));
    for (int i = 0; i < kOtherOrderCount; ++i)
      if (at_order[i]) std::printf(" %s %.2f %%", kOtherOrderNames[i], Score::pct(at_order[i], tracked));
    std::printf(" | longest lock on another order %.1f s, %zu over %.1f s\n", longest_lock_s, long_locks,
                kLockLimitS);
    std::printf("      every estimate: %5.1f %% of in-band hops, %5.1f %% right, mean confidence %.3f\n",
                Score::pct(valued, in_band), Score::pct(valued_right, valued),
                valued ? confidence_sum / static_cast<double>(valued) : NAN);
    calibration.print();
  }
};

// Feeds `x` to a tracker in capture-sized blocks; calls `sink` with every decided output (with a decision
// lag, the hop's confidence decided with the windows after it; the outputs at once are drained unread).
// Returns the CPU time spent in the tracker. push_frames() alone leaves the stream open for more frames
// (finish_stream() ends it); run_tracker() does both.
template <class Sink>
double push_frames(SlidingDftTracker& tracker, std::span<const float> x, Sink&& sink) {
  const std::size_t block = std::min<std::size_t>(4800, tracker.max_push_frames());
  double spent = 0.0;
  TrackPoint p;
  for (std::size_t at = 0; at < x.size(); at += block) {
    const double before = cpu_seconds();
    tracker.push(x.subspan(at, std::min(block, x.size() - at)));
    spent += cpu_seconds() - before;
    while (tracker.pop(p)) {
    }
    while (tracker.pop_decided(p))
      sink(p);
  }
  return spent;
}

// Ends the stream: the outputs held back for the decision lag go to `sink`.
template <class Sink>
void finish_stream(SlidingDftTracker& tracker, Sink&& sink) {
  tracker.finish();
  TrackPoint p;
  while (tracker.pop(p)) {
  }
  while (tracker.pop_decided(p))
    sink(p);
}

template <class Sink>
double run_tracker(SlidingDftTracker& tracker, std::span<const float> x, Sink&& sink) {
  const double spent = push_frames(tracker, x, sink);
  finish_stream(tracker, sink);
  return spent;
}

struct Case {
  std::string vehicle = "drive";
  double fs = 48000.0;
  double snr_db = 0.0;
  double duration_s = 180.0;
  std::uint64_t seed = 11;
  double harmonic2 = 0.5, harmonic3 = 0.3, half_order = 0.3;  // the generator's default mix
  double tone_hz = 137.0;
  double tone_amplitude = 0.0;
};

struct Result {
  Score ours, plain;
  double crb = 0.0;
};

// One generated drive at one SNR, scored: the tracker, the plain FFT peak and the Cramer-Rao bound.
Result accuracy(const Case& c);
void print_line(const Case& c, const Result& r);
void print_valued(const Score& s);
// 0 dB over other seeds, vehicles, harmonic mixes, interfering tones and rates; pooled figures.
void generalisation(std::uint64_t seed);
// CPU time for 10 minutes of 48 kHz audio.
void cpu();

// The scenes of one seed set ("tuning", "report" or "check") with the components `without` switched off,
// at each of `snrs`; with clip_s > 0, also cut into clips of clip_s, each tracked from a cold start.
int scenes(const std::string& set, const TrackerConfig& base, const std::vector<std::string>& without,
           const std::vector<double>& snrs, double clip_s = 0.0);

struct WavOptions {
  std::string wav, tacho;
  double order = 2.0;
  double offset_s = 0.0;  // tacho time of the recording's first frame
  // Longest interval between two tacho rows that the truth is interpolated across (s); 0: from the log, 1.5
  // times its median interval (a row missing from its own polling), at least 1 s.
  double tacho_gap_s = 0.0;
  int channel = -1;
  TrackerConfig config;
  bool dump = false;
};

// Scores a real recording against its tacho log; the figures go through `required` (--require). 1 when no
// hop of the recording has a truth in the band (the reason on stderr), else required's exit status.
int score_wav(WavOptions o, Requirements& required);

}  // namespace gearpulse::bench::tracker_bench
