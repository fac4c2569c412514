#include <sndfile.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "bench/tracker/tracker.hpp"

namespace gearpulse::bench::tracker_bench {
namespace {

struct SndfileCloser {
  void operator()(SNDFILE* f) const noexcept { sf_close(f); }
};

// Tacho samples (t, rpm) in time order. A row's first two fields are t and rpm, separated by a comma or
// spaces, or by a semicolon or a tab, in which case a comma is the decimal mark ("1,5;800", as spreadsheets
// in many locales write it); a line that does not read so (a header, a gap marked "-") is skipped and
// counted.
// Rows that share a time (a log written with whole seconds and polled faster) are one sample, their mean; a
// time before the row above is an error naming the line.
struct Tacho {
  std::vector<std::array<double, 2>> rows;
  std::size_t merged = 0;     // rows that shared a time with the row above
  std::size_t skipped = 0;    // lines that are not two numbers (blank lines aside)
  std::string first_skipped;  // "line N: text" of the first of them
};

// t and rpm from one line, or false.
bool parse_tacho_row(std::string line, double& t, double& rpm) {
  if (line.find_first_of(";\t") != std::string::npos) {
    std::replace(line.begin(), line.end(), ',', '.');
    std::replace(line.begin(), line.end(), ';', ',');
    std::replace(line.begin(), line.end(), '\t', ',');
  }
  const char* p = line.c_str();
  char* end = nullptr;
  t = std::strtod(p, &end);
  if (end == p) return false;
  p = end;
  const char* sep = p;
  while (*p == ' ' || *p == ',')
    ++p;
  if (p == sep || std::count(sep, p, ',') > 1) return false;  // no separator, or an empty field between
  rpm = std::strtod(p, &end);
  if (end == p) return false;
  while (*end == ' ' || *end == '\r')
    ++end;
  return (*end == '\0' || *end == ',') && std::isfinite(t) && std::isfinite(rpm);
}

Tacho read_tacho(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  Tacho tacho;
  auto& rows = tacho.rows;
  std::size_t same = 1;  // rows averaged into the last sample
  std::string line;
  for (std::size_t number = 1; std::getline(in, line); ++number) {
    double t = 0.0, rpm = 0.0;
    if (!parse_tacho_row(line, t, rpm)) {
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      if (tacho.skipped++ == 0)
        tacho.first_skipped = "line " + std::to_string(number) + ": '" +
                              line.substr(0, std::min(line.find_last_not_of('\r') + 1, std::size_t{60})) +
                              "'";
      continue;
    }
    if (!rows.empty() && t == rows.back()[0]) {
      rows.back()[1] += (rpm - rows.back()[1]) / static_cast<double>(++same);
      ++tacho.merged;
      continue;
    }
    if (!rows.empty() && t < rows.back()[0]) {
      char what[160];
      std::snprintf(what, sizeof what, ":%zu: time %g is before the row above's %g: times must increase",
                    number, t, rows.back()[0]);
      throw std::runtime_error(path + what);
    }
    rows.push_back({t, rpm});
    same = 1;
  }
  if (rows.size() < 2)
    throw std::runtime_error(path + ": fewer than two t,rpm rows" +
                             (tacho.skipped > 0
                                  ? " (" + std::to_string(tacho.skipped) +
                                        " line(s) not two numbers; first, " + tacho.first_skipped + ")"
                                  : std::string()));
  return tacho;
}

// The truth at a hop: the rpm linearly interpolated between the tacho rows around it, / 60 x order, and the
// range between those two rows' values (where the revs were, if they moved one way between the rows).
struct Truth {
  double at = NAN, lo = NAN, hi = NAN;
};

// Truth at t from tacho rows at most max_gap_s apart; NaN outside the log, across a gap, or with the engine
// stopped.
Truth tacho_truth(const std::vector<std::array<double, 2>>& tacho, double t, double order, double max_gap_s) {
  const auto it = std::lower_bound(tacho.begin(), tacho.end(), t,
                                   [](const std::array<double, 2>& r, double v) { return r[0] < v; });
  if (it == tacho.begin() || it == tacho.end()) {
    if (it == tacho.end() || (*it)[0] != t || !((*it)[1] > 0.0)) return {};
    const double f = (*it)[1] / 60.0 * order;
    return {f, f, f};
  }
  const auto& b = *it;
  const auto& a = *(it - 1);
  if (b[0] - a[0] > max_gap_s || !(a[1] > 0.0) || !(b[1] > 0.0)) return {};
  const double rpm = a[1] + (t - a[0]) / (b[0] - a[0]) * (b[1] - a[1]);
  return {rpm / 60.0 * order, std::min(a[1], b[1]) / 60.0 * order, std::max(a[1], b[1]) / 60.0 * order};
}

// The longest interval between tacho rows (times ascending) interpolated across when none is given: 1.5
// times the log's median interval (a row missing from its own polling), at least 1 s.
double tacho_gap_s(const std::vector<std::array<double, 2>>& rows) {
  std::vector<double> steps;
  for (std::size_t i = 1; i < rows.size(); ++i)
    steps.push_back(rows[i][0] - rows[i - 1][0]);
  if (steps.empty()) return 1.0;
  const auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
  std::nth_element(steps.begin(), mid, steps.end());
  return std::max(1.0, 1.5 * *mid);
}

}  // namespace

int score_wav(WavOptions o, Requirements& required) {
  const Tacho log = read_tacho(o.tacho);
  const auto& tacho = log.rows;
  const double gap = o.tacho_gap_s > 0.0 ? o.tacho_gap_s : tacho_gap_s(tacho);
  SF_INFO info{};
  std::unique_ptr<SNDFILE, SndfileCloser> file(sf_open(o.wav.c_str(), SFM_READ, &info));
  if (!file) throw std::runtime_error(o.wav + ": cannot read audio: " + sf_strerror(nullptr));
  if (info.frames <= 0 || info.channels <= 0) throw std::runtime_error(o.wav + ": no audio frames");
  if (o.channel >= info.channels)
    throw std::runtime_error(o.wav + ": --channel " + std::to_string(o.channel) + " but the file has " +
                             std::to_string(info.channels) + " channel(s), counted from 0");
  o.config.sample_rate_hz = info.samplerate;
  o.config.history_s = 0.0;
  std::string error;
  auto tracker = SlidingDftTracker::create(o.config, error);
  if (!tracker) throw std::runtime_error(o.wav + ": " + error);
  // Scored against the interpolated truth, and against the range between the tacho rows around each hop
  // (the value in that range nearest the estimate): a log polled every second or slower puts a shift's
  // fall, or a ramp's bend, between two rows, where the interpolation is not where the revs were.
  OrderScore s, ranged;
  for (OrderScore* score : {&s, &ranged}) {
    score->band_lo = o.config.band_lo_hz;
    score->band_hi = o.config.band_hi_hz;
    score->hop_s = o.config.hop_s;
  }
  const auto score_hop = [&](const TrackPoint& p) {
    const Truth truth = tacho_truth(tacho, p.t + o.offset_s, o.order, gap);
    if (o.dump)
      std::printf("%.3f %.3f %.3f %.1f %d %.3f\n", p.t, truth.at, p.freq, p.snr_db, p.tracked, p.confidence);
    s.add(p, truth.at);
    // The same hops as in-band (the interpolated truth's), the range's value kept in the band.
    const bool in_band = truth.at >= o.config.band_lo_hz && truth.at <= o.config.band_hi_hz;
    ranged.add(p, in_band && std::isfinite(p.freq) ? std::clamp(std::clamp(p.freq, truth.lo, truth.hi),
                                                                o.config.band_lo_hz, o.config.band_hi_hz)
                                                   : truth.at);
  };
  // The recording read in blocks (a long one need not fit in memory).
  constexpr sf_count_t kBlock = 1 << 16;
  const auto channels = static_cast<std::size_t>(info.channels);
  std::vector<float> interleaved(static_cast<std::size_t>(kBlock) * channels);
  std::vector<float> mono(static_cast<std::size_t>(kBlock));
  sf_count_t frames = 0;
  double spent = 0.0;
  for (sf_count_t got = 0; (got = sf_readf_float(file.get(), interleaved.data(), kBlock)) > 0;) {
    frames += got;
    const std::size_t n = gearpulse::extract_channel(
        std::span<const float>(interleaved.data(), static_cast<std::size_t>(got) * channels), info.channels,
        o.channel, mono);
    spent += push_frames(*tracker, std::span<const float>(mono.data(), n), score_hop);
  }
  finish_stream(*tracker, score_hop);
  if (sf_error(file.get()) != SF_ERR_NO_ERROR)
    throw std::runtime_error(o.wav + ": read error after " + std::to_string(frames) +
                             " frames: " + sf_strerror(file.get()));
  const double seconds = static_cast<double>(frames) / info.samplerate;
  std::printf("%s (%.1f s at %d Hz, channel %s) against %s x %g / 60, band %g:%g Hz, window %g s, hop %g s\n",
              o.wav.c_str(), seconds, info.samplerate,
              o.channel < 0 ? "mix" : std::to_string(o.channel).c_str(), o.tacho.c_str(), o.order,
              o.config.band_lo_hz, o.config.band_hi_hz, o.config.window_s, o.config.hop_s);
  std::printf("tacho: %zu rows over %.1f-%.1f s, interpolated across intervals up to %.2f s (%s)",
              tacho.size(), tacho.front()[0], tacho.back()[0], gap,
              o.tacho_gap_s > 0.0 ? "--tacho-gap" : "1.5 x the median interval, at least 1 s");
  if (log.merged > 0)
    std::printf("; %zu row(s) sharing a time with the row above averaged into it", log.merged);
  if (log.skipped > 0)
    std::printf("; %zu line(s) not two numbers skipped (first, %s)", log.skipped, log.first_skipped.c_str());
  std::printf("\n");
  if (s.in_band == 0) {
    std::fprintf(stderr,
                 "bench_tracker: no hop of %s has a truth in the band %g:%g Hz: check that the tacho's t is "
                 "on the recording's clock (--offset), the order (--order %g: rpm / 60 x %g), the band "
                 "(--band) and the intervals the truth is interpolated across (--tacho-gap)\n",
                 o.wav.c_str(), o.config.band_lo_hz, o.config.band_hi_hz, o.order, o.order);
    return 1;
  }
  s.print("recording");
  ranged.print("recording, truth as the range between tacho rows");
  std::printf("CPU: %.2f s (%.3f %% of one core)\n", spent, 100.0 * spent / std::max(seconds, 1e-9));
  required.report("in_band_hops", static_cast<double>(s.in_band));
  required.report("coverage_pct", Score::pct(s.tracked, s.in_band));
  required.report("gross_pct", Score::pct(s.gross, s.tracked));
  required.report("rmse_hz", s.right_n ? std::sqrt(s.sq / static_cast<double>(s.right_n)) : NAN);
  required.report("longest_lock_s", s.longest_lock_s);
  required.report("gross_range_pct", Score::pct(ranged.gross, ranged.tracked));
  return required.exit_status();
}

}  // namespace gearpulse::bench::tracker_bench
