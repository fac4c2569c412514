#include <sndfile.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench/tracker/tracker.hpp"

namespace gearpulse::bench::tracker_bench {
namespace {

struct SndfileCloser {
  void operator()(SNDFILE* f) const noexcept { sf_close(f); }
};

// Tacho samples (t, rpm) in time order; a line that does not parse as two numbers is skipped.
std::vector<std::array<double, 2>> read_tacho(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::vector<std::array<double, 2>> rows;
  std::string line;
  while (std::getline(in, line)) {
    double t = 0.0, rpm = 0.0;
    if (std::sscanf(line.c_str(), "%lf,%lf", &t, &rpm) != 2 || !std::isfinite(t)) continue;
    if (!rows.empty() && t <= rows.back()[0]) throw std::runtime_error(path + ": times must increase");
    rows.push_back({t, rpm});
  }
  if (rows.size() < 2) throw std::runtime_error(path + ": fewer than two t,rpm rows");
  return rows;
}

// Truth at t: rpm linearly interpolated between tacho samples at most 1 s apart, / 60 x order; NaN
// outside the log, across a gap, or with the engine stopped.
double tacho_truth(const std::vector<std::array<double, 2>>& tacho, double t, double order) {
  constexpr double kMaxGapS = 1.0;
  const auto it = std::lower_bound(tacho.begin(), tacho.end(), t,
                                   [](const std::array<double, 2>& r, double v) { return r[0] < v; });
  if (it == tacho.begin() || it == tacho.end())
    return it != tacho.end() && (*it)[0] == t ? (*it)[1] / 60.0 * order : NAN;
  const auto& b = *it;
  const auto& a = *(it - 1);
  if (b[0] - a[0] > kMaxGapS) return NAN;
  const double rpm = a[1] + (t - a[0]) / (b[0] - a[0]) * (b[1] - a[1]);
  return rpm > 0.0 ? rpm / 60.0 * order : NAN;
}

}  // namespace

int score_wav(WavOptions o) {
  const auto tacho = read_tacho(o.tacho);
  SF_INFO info{};
  std::unique_ptr<SNDFILE, SndfileCloser> file(sf_open(o.wav.c_str(), SFM_READ, &info));
  if (!file) throw std::runtime_error(o.wav + ": cannot read audio: " + sf_strerror(nullptr));
  if (info.frames <= 0 || info.channels <= 0) throw std::runtime_error(o.wav + ": no audio frames");
  if (o.channel >= info.channels) throw std::runtime_error(o.wav + ": no such channel");
  std::vector<float> interleaved(static_cast<std::size_t>(info.frames) *
                                 static_cast<std::size_t>(info.channels));
  const sf_count_t got = sf_readf_float(file.get(), interleaved.data(), info.frames);
  std::vector<float> mono(static_cast<std::size_t>(std::max<sf_count_t>(got, 0)));
  (void)gearpulse::extract_channel(interleaved, info.channels, o.channel, mono);
  o.config.sample_rate_hz = info.samplerate;
  o.config.history_s = 0.0;
  std::string error;
  auto tracker = SlidingDftTracker::create(o.config, error);
  if (!tracker) throw std::runtime_error(o.wav + ": " + error);
  OrderScore s;
  s.band_lo = o.config.band_lo_hz;
  s.band_hi = o.config.band_hi_hz;
  s.hop_s = o.config.hop_s;
  const double spent = run_tracker(*tracker, mono, [&](const TrackPoint& p) {
    const double truth = tacho_truth(tacho, p.t + o.offset_s, o.order);
    if (o.dump)
      std::printf("%.3f %.3f %.3f %.1f %d %.3f\n", p.t, truth, p.freq, p.snr_db, p.tracked, p.confidence);
    s.add(p, truth);
  });
  const double seconds = static_cast<double>(mono.size()) / info.samplerate;
  std::printf("%s (%.1f s at %d Hz, channel %s) against %s x %g / 60, band %g:%g Hz, window %g s, hop %g s\n",
              o.wav.c_str(), seconds, info.samplerate,
              o.channel < 0 ? "mix" : std::to_string(o.channel).c_str(), o.tacho.c_str(), o.order,
              o.config.band_lo_hz, o.config.band_hi_hz, o.config.window_s, o.config.hop_s);
  s.print("recording");
  std::printf("CPU: %.2f s (%.3f %% of one core)\n", spent, 100.0 * spent / std::max(seconds, 1e-9));
  return 0;
}

}  // namespace gearpulse::bench::tracker_bench
