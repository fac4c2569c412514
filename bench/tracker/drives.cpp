#include <fftw3.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "bench/tracker/tracker.hpp"
#include "tools/sim/lighter_signal.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace gearpulse::bench::tracker_bench {
namespace {

// Argmax bin of a rectangular FFT of the tracker's window length inside the band, no interpolation.
class FftPeakTracker {
 public:
  FftPeakTracker(double fs, double window_s)
      : fs_(fs),
        n_(static_cast<int>(std::lround(window_s * fs))),
        in_(static_cast<std::size_t>(n_)),
        out_(static_cast<std::size_t>(n_ / 2 + 1)) {
    plan_ = fftw_plan_dft_r2c_1d(n_, in_.data(), reinterpret_cast<fftw_complex*>(out_.data()), FFTW_ESTIMATE);
  }
  ~FftPeakTracker() { fftw_destroy_plan(plan_); }
  FftPeakTracker(const FftPeakTracker&) = delete;
  FftPeakTracker& operator=(const FftPeakTracker&) = delete;
  double estimate(const std::vector<float>& x, double centre_s) {
    const long start = std::lround(centre_s * fs_) - n_ / 2;
    if (start < 0 || start + n_ > static_cast<long>(x.size())) return NAN;
    double mean = 0.0;
    for (int i = 0; i < n_; ++i)
      mean += x[static_cast<std::size_t>(start + i)];
    mean /= n_;
    for (int i = 0; i < n_; ++i)
      in_[static_cast<std::size_t>(i)] = x[static_cast<std::size_t>(start + i)] - mean;
    fftw_execute(plan_);
    const double bin = fs_ / n_;
    int best = -1;
    double best_p = -1.0;
    for (int k = static_cast<int>(std::ceil(50.0 / bin)); k <= static_cast<int>(200.0 / bin); ++k) {
      const auto& c = out_[static_cast<std::size_t>(k)];
      const double p = c[0] * c[0] + c[1] * c[1];
      if (p > best_p) {
        best_p = p;
        best = k;
      }
    }
    return best * bin;
  }

 private:
  double fs_;
  int n_;
  std::vector<double> in_;
  std::vector<std::array<double, 2>> out_;
  fftw_plan plan_;
};

// Engine frequency of a drive: the built-in drive, or a preset of the vehicle simulator. The
// simulator's engine component runs from ~13 Hz at idle; the ripple the tracker follows is a multiple of
// it, taken here so that the rev limiter sits at the band's top (idle then falls below the band).
sim::FrequencyTrajectory drive_of(const std::string& vehicle, double duration_s, std::uint64_t seed) {
  if (vehicle == "drive") return sim::drive_trajectory(duration_s, seed);
  sim::DriveOptions options;
  options.duration = duration_s + 1.0;
  options.dt = 0.01;
  options.seed = seed;
  const sim::Vehicle car = sim::vehicle_preset(vehicle);
  const sim::Drive drive = sim::simulate_drive(car, options);
  const double multiple = 200.0 / car.max_freq;
  std::vector<double> freq;
  freq.reserve(drive.truth.size());
  for (const sim::TruthSample& t : drive.truth)
    freq.push_back(t.freq * multiple);
  return sim::trajectory_from_samples(std::move(freq), 1.0 / options.dt);
}

}  // namespace

Result accuracy(const Case& c) {
  const auto trajectory = drive_of(c.vehicle, c.duration_s, c.seed);
  sim::LighterSignalConfig cfg;
  cfg.sample_rate_hz = c.fs;
  cfg.snr_db = c.snr_db;
  cfg.harmonic2 = c.harmonic2;
  cfg.harmonic3 = c.harmonic3;
  cfg.half_order = c.half_order;
  cfg.tone_hz = c.tone_hz;
  cfg.tone_amplitude = c.tone_amplitude;
  cfg.seed = c.seed;
  const std::vector<float> x = sim::make_lighter_signal(cfg, trajectory, c.duration_s);

  TrackerConfig tc;
  tc.sample_rate_hz = c.fs;
  SlidingDftTracker tracker(tc);
  Result r;
  FftPeakTracker fft(c.fs, tc.window_s);
  TrackPoint p;
  const double n = std::round(tc.window_s * c.fs);
  const double sigma2 =
      cfg.amplitude * cfg.amplitude / 2.0 / std::pow(10.0, c.snr_db / 10.0) * (c.fs / 2.0) / 150.0;
  // Single-tone CRB of the frequency (Hz^2) for N samples at fs (Rife & Boorstyn).
  r.crb = std::sqrt(
      12.0 * sigma2 * c.fs * c.fs /
      (4.0 * std::numbers::pi * std::numbers::pi * cfg.amplitude * cfg.amplitude * n * (n * n - 1.0)));
  const bool dump = std::getenv("GEARPULSE_BENCH_DUMP") != nullptr;
  const auto block = static_cast<std::size_t>(c.fs / 10);
  for (std::size_t at = 0; at < x.size(); at += block) {
    tracker.push(std::span<const float>(x).subspan(at, std::min(block, x.size() - at)));
    while (tracker.pop(p)) {
      const double truth = trajectory(p.t);
      if (dump)
        std::printf("%.2f %.2f %.2f %.1f %d %.3f\n", p.t, truth, p.freq, p.snr_db, p.tracked, p.confidence);
      if (in_band(truth)) {
        r.ours.add_in_band(p, truth);
        r.plain.add_in_band(true, fft.estimate(x, p.t), truth);
      } else {
        r.ours.add_out_band(p.tracked, p.freq, truth);
      }
    }
  }
  return r;
}

void print_line(const Case& c, const Result& r) {
  std::printf(
      "%7.0f Hz %5.1f dB | ours: rmse %6.3f Hz gross %5.2f %% tracked %5.1f %% false %4.1f %% | "
      "fft-peak: rmse %6.3f Hz gross %5.2f %% | CRB rmse %6.3f Hz | in-band hops %zu\n",
      c.fs, c.snr_db, r.ours.rmse(), r.ours.gross_pct(), r.ours.tracked_pct(), r.ours.false_pct(),
      r.plain.rmse(), r.plain.gross_pct(), r.crb, r.ours.in_band);
}

void print_valued(const Score& s) {
  std::printf("      every hop with an estimate (any confidence): %5.1f %% of in-band hops, %5.2f %% gross\n",
              s.valued_pct(), s.valued_gross_pct());
}

void generalisation(std::uint64_t seed) {
  struct Mix {
    const char* name;
    double h2, h3, half;
  };
  const Mix mixes[] = {{"default", 0.5, 0.3, 0.3},
                       {"weak-harmonics", 0.25, 0.12, 0.12},
                       {"strong-2nd", 1.2, 0.3, 0.2},
                       {"no-half-order", 0.5, 0.3, 0.0}};
  const char* vehicles[] = {"drive", "bmw-520i", "hatch-5", "van-6", "sport-7", "compact-4"};
  const double rates[] = {48000.0, 44100.0, 8000.0, 5100.0};
  std::mt19937_64 rng(seed);
  std::printf("0 dB over other seeds, vehicles, harmonic mixes, fixed tones and rates (120 s each):\n");
  Score pooled;
  for (int i = 0; i < 8; ++i) {
    Case c;
    c.vehicle = vehicles[i % 6];
    c.fs = rates[i % 4];
    c.duration_s = 120.0;
    c.seed = seed + 100 + static_cast<std::uint64_t>(i);
    const Mix& m = mixes[(i / 2) % 4];
    c.harmonic2 = m.h2;
    c.harmonic3 = m.h3;
    c.half_order = m.half;
    if (i % 2 == 1) {
      c.tone_hz = std::uniform_real_distribution<double>(60.0, 190.0)(rng);
      c.tone_amplitude = std::uniform_real_distribution<double>(0.5, 1.5)(rng);
    }
    const Result r = accuracy(c);
    std::printf(
        "  %-9s %-14s %7.0f Hz tone %s%5.0f Hz x%.1f | rmse %6.3f Hz gross %5.2f %% tracked %5.1f %% false "
        "%4.1f %% | in-band hops %zu\n",
        c.vehicle.c_str(), m.name, c.fs, c.tone_amplitude > 0 ? "" : "none",
        c.tone_amplitude > 0 ? c.tone_hz : 0.0, c.tone_amplitude, r.ours.rmse(), r.ours.gross_pct(),
        r.ours.tracked_pct(), r.ours.false_pct(), r.ours.in_band);
    pooled.merge(r.ours);
  }
  std::printf("  pooled: rmse %.3f Hz gross %.2f %% tracked %.1f %% false %.1f %%\n", pooled.rmse(),
              pooled.gross_pct(), pooled.tracked_pct(), pooled.false_pct());
  print_valued(pooled);
  pooled.calibration.print();
}

void cpu() {
  constexpr double kFs = 48000.0;
  constexpr double kMinutes = 10.0;
  const auto trajectory = sim::drive_trajectory(kMinutes * 60.0, 7);
  sim::LighterSignalConfig cfg;
  cfg.snr_db = 0.0;
  cfg.seed = 7;
  sim::LighterSignal gen(cfg, trajectory);
  TrackerConfig tc;
  SlidingDftTracker tracker(tc);
  std::vector<float> block(4800);
  double spent = 0.0;
  std::size_t outputs = 0;
  for (double t = 0.0; t < kMinutes * 60.0; t += 0.1) {
    gen.generate(block);
    const double before = cpu_seconds();
    tracker.push(block);
    TrackPoint p;
    while (tracker.pop(p))
      ++outputs;
    spent += cpu_seconds() - before;
  }
  std::printf("CPU: %.0f min of %.0f Hz audio tracked in %.2f s CPU (%.3f %% of one core), %zu outputs\n",
              kMinutes, kFs, spent, 100.0 * spent / (kMinutes * 60.0), outputs);
}

}  // namespace gearpulse::bench::tracker_bench
