// The tracker's interface and configuration: pushes and pops, refused configurations, no allocation per
// hop, output times, start(), at(), holes in the stream, extract_channel, silence and clipping, and the fit
// of a window's orders. Clean lines are tracker_clean_test.cpp, noise and harmonics tracker_noise_test.cpp,
// the generated scenes tracker_scenes_test.cpp.
// The test replaces the global operator new/delete with counting ones over malloc/free, which GCC's
// allocation-pairing analysis cannot see through.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <numbers>
#include <span>
#include <string>
#include <vector>

#include "core/sinusoid_fit.hpp"
#include "core/sliding_dft_tracker.hpp"
#include "tests/alloc_counter.hpp"
#include "tests/core/tracker_run.hpp"
#include "tools/sim/lighter_signal.hpp"

using gearpulse::SlidingDftTracker;
using gearpulse::TrackerConfig;
using gearpulse::TrackPoint;
namespace sim = gearpulse::sim;
using namespace gearpulse::test::tracker_run;

using gearpulse::test::g_allocations;
using gearpulse::test::g_counting;

TEST_CASE("tracker: pushes of max_push_frames() popped after each lose no output, longer ones do") {
  TrackerConfig c = config_at(8000.0);
  c.hop_s = 0.005;  // the shortest hop the daemon takes
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  const auto x = sim::make_lighter_signal(
      g, [](double) { return 100.0; }, 30.0);
  SlidingDftTracker fits(c);
  REQUIRE(fits.max_push_frames() < x.size());
  const auto points = track(fits, x, fits.max_push_frames());
  CHECK(fits.dropped_outputs() == 0);
  CHECK(points.size() >= static_cast<std::size_t>(29.8 / c.hop_s));
  SlidingDftTracker whole(c);
  (void)track(whole, x, x.size());  // one push of 30 s: 6000 hops against a queue of a few hundred
  CHECK(whole.dropped_outputs() > 0);
}

TEST_CASE("tracker: silence and clipping give no crash and a sensible output") {
  SECTION("digital silence with a supply level") {
    std::vector<float> x(48000 * 3, 0.6f);
    SlidingDftTracker tracker(config_at(48000.0));
    const auto points = track(tracker, x);
    REQUIRE(points.size() >= 25);
    for (const TrackPoint& p : points) {
      CHECK_FALSE(p.tracked);
      CHECK(std::isnan(p.freq));
    }
  }
  SECTION("a hard-clipped recording is still tracked") {
    const sim::FrequencyTrajectory truth = [](double t) { return 100.0 + 10.0 * t; };
    sim::LighterSignalConfig g;
    g.amplitude = 1.0;
    g.clip = 0.4;
    g.snr_db = 20.0;
    g.seed = 9;
    SlidingDftTracker tracker(config_at(g.sample_rate_hz));
    const auto points = track(tracker, sim::make_lighter_signal(g, truth, 4.0));
    const Stats s = score(points, truth, 0.5, 4.0);
    CHECK(s.tracked_fraction >= 0.9);
    CHECK(s.rmse <= 0.5);
  }
  SECTION("non-finite samples do not poison the stream") {
    const sim::FrequencyTrajectory truth = [](double) { return 110.0; };
    sim::LighterSignalConfig g;
    g.seed = 10;
    auto x = sim::make_lighter_signal(g, truth, 5.0);
    x[48000] = NAN;
    x[48001] = INFINITY;
    SlidingDftTracker tracker(config_at(g.sample_rate_hz));
    const auto points = track(tracker, x);
    const Stats s = score(points, truth, 2.5, 5.0);
    CHECK(s.tracked_fraction >= 0.9);
    CHECK(s.rmse <= 0.5);
  }
}

TEST_CASE("tracker: invalid configurations are rejected with a reason") {
  const auto rejected = [](TrackerConfig c, const char* word) {
    std::string error;
    CHECK(SlidingDftTracker::create(c, error) == nullptr);
    CHECK(error.find(word) != std::string::npos);
    CHECK_THROWS_AS(SlidingDftTracker{c}, std::invalid_argument);
  };
  TrackerConfig c = config_at(8000.0);
  c.band_hi_hz = 4500.0;
  rejected(c, "Nyquist");
  c = config_at(440.0);
  rejected(c, "too low");
  c = config_at(48000.0);
  c.window_s = 0.05;
  rejected(c, "too short");
  c = config_at(48000.0);
  c.hop_s = 0.0;
  rejected(c, "hop");
  c = config_at(48000.0);
  c.band_lo_hz = 200.0;
  c.band_hi_hz = 50.0;
  rejected(c, "band");
  c = config_at(NAN);
  rejected(c, "sample rate");
  c = config_at(48000.0);
  c.max_slew_hz_per_s = 1e12;  // its gate in bins would overflow an int
  rejected(c, "max slew");
  c = config_at(48000.0);
  c.shift_slew_hz_per_s = 1e12;
  rejected(c, "shift slew");
  c = config_at(48000.0);
  c.decision_lag_s = -0.1;
  rejected(c, "decision lag");
  c = config_at(48000.0);
  c.hop_s = 0.01;
  c.decision_lag_s = 0.65;  // 65 hops held back: more than the queue keeps beside a push's hops
  rejected(c, "decision lag");
  c.decision_lag_s = 0.64;
  CHECK(SlidingDftTracker::validate(c).empty());
  std::string error;
  CHECK(SlidingDftTracker::create(config_at(5100.0), error) != nullptr);
  CHECK(error.empty());
}

TEST_CASE("tracker: no allocation per hop") {
  const double lag = GENERATE(0.0, 0.3);  // with and without the fixed-lag decision
  INFO("decision lag " << lag << " s");
  const sim::FrequencyTrajectory truth = [](double t) { return 90.0 + 8.0 * t; };
  sim::LighterSignalConfig g;
  g.seed = 11;
  const auto x = sim::make_lighter_signal(g, truth, 5.0);
  TrackerConfig c = config_at(g.sample_rate_hz);
  c.hop_s = 0.05;
  c.decision_lag_s = lag;
  SlidingDftTracker tracker(c);
  std::size_t outputs = 0, decided = 0, tracked = 0, served = 0;
  TrackPoint p;
  g_allocations = 0;
  g_counting = true;
  for (std::size_t at = 0; at < x.size(); at += 960) {
    tracker.push(std::span<const float>(x).subspan(at, std::min<std::size_t>(960, x.size() - at)));
    while (tracker.pop(p)) {
      ++outputs;
      tracked += p.tracked;
    }
    while (tracker.pop_decided(p))
      ++decided;
    const TrackPoint q = tracker.at(tracker.latest_time() - 0.2);
    const TrackPoint r = tracker.nearest(q.t);
    served += q.tracked && r.tracked;
  }
  tracker.skip(100);
  tracker.retime(10.0);
  tracker.finish();
  while (tracker.pop(p))
    ++outputs;
  while (tracker.pop_decided(p))
    ++decided;
  g_counting = false;
  CHECK(g_allocations.load() == 0);
  CHECK(outputs >= 95);
  CHECK(decided == outputs);
  CHECK(tracked >= 85);
  CHECK(served >= 40);
}

TEST_CASE("tracker: output times are window centres in the caller's time base") {
  TrackerConfig c = config_at(8000.0);
  c.hop_s = 0.05;
  SlidingDftTracker tracker(c);
  tracker.start(1000.0);
  // A window centred at t needs frames up to t + window/2 (plus the filter's half length).
  std::vector<float> x(8000 * 2, 0.0f);
  const auto points = track(tracker, x, 7);
  REQUIRE(points.size() >= 30);
  for (std::size_t i = 1; i < points.size(); ++i)
    CHECK(points[i].t - points[i - 1].t == Approx(0.05).margin(1e-9));
  CHECK(std::fmod(points[0].t - 1000.0 + 1e-9, 0.05) < 1e-6);
  CHECK(points.back().t <= 1002.0 - 0.05);
  CHECK(tracker.latest_time() < 1002.0 - 0.05);
  CHECK(tracker.latest_time() >= points.back().t);

  SECTION("a frequency step shows at the window centre") {
    const sim::FrequencyTrajectory truth = [](double t) { return t < 2.0 ? 80.0 : 120.0; };
    sim::LighterSignalConfig g;
    g.sample_rate_hz = 8000.0;
    g.snr_db = 20.0;
    g.seed = 12;
    SlidingDftTracker t2(config_at(8000.0));
    const auto pts = track(t2, sim::make_lighter_signal(g, truth, 4.0));
    for (const TrackPoint& p : pts) {
      if (!p.tracked) continue;
      if (p.t <= 1.9) CHECK(p.freq == Approx(80.0).margin(1.0));
      if (p.t >= 2.1 + 0.4) CHECK(p.freq == Approx(120.0).margin(1.0));
    }
  }
}

// start() begins a new stream (another source, a reopened device): nothing learned from the one before
// may shape the new one's output, neither its tones nor whether its signal has a half order.
TEST_CASE("tracker: after start() it tracks as a fresh tracker does, whatever it heard before") {
  const double fs = 8000.0;
  sim::LighterSignalConfig loud;  // a loud line without a half order: teaches its absence
  loud.sample_rate_hz = fs;
  loud.snr_db = 40.0;
  loud.half_order = 0.0;
  loud.tone_hz = 150.0;  // and a fixed tone to learn
  loud.seed = 15;
  sim::LighterSignalConfig next;
  next.sample_rate_hz = fs;
  next.snr_db = 5.0;
  next.seed = 16;
  const sim::FrequencyTrajectory before = [](double t) { return 60.0 + 8.0 * t; };
  const sim::FrequencyTrajectory after = [](double t) { return 45.0 + 15.0 * t + 3.0 * std::sin(3.0 * t); };
  const auto x = sim::make_lighter_signal(next, after, 8.0);

  SlidingDftTracker fresh(config_at(fs));
  const auto expected = track(fresh, x);
  SlidingDftTracker reused(config_at(fs));
  (void)track(reused, sim::make_lighter_signal(loud, before, 10.0));
  reused.start(0.0);
  const auto got = track(reused, x);
  REQUIRE(got.size() == expected.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const TrackPoint& a = got[i];
    const TrackPoint& b = expected[i];
    const bool same_freq = (std::isnan(a.freq) && std::isnan(b.freq)) || a.freq == b.freq;
    differ += !(a.t == b.t && same_freq && a.tracked == b.tracked && a.confidence == b.confidence);
  }
  CHECK(differ == 0);
}

TEST_CASE("tracker: at() estimates a window centred on any recent time") {
  const sim::FrequencyTrajectory truth = [](double t) { return 80.0 + 15.0 * t; };
  sim::LighterSignalConfig g;
  g.snr_db = 10.0;
  g.seed = 13;
  const auto x = sim::make_lighter_signal(g, truth, 4.0);
  TrackerConfig c = config_at(g.sample_rate_hz);
  c.history_s = 2.0;
  SlidingDftTracker tracker(c);
  tracker.start(500.0);
  (void)track(tracker, x);
  double sq = 0.0;
  int n = 0;
  for (double t = 502.2; t < 503.9; t += 0.137) {
    const TrackPoint p = tracker.at(t);
    CHECK(p.t == Approx(t).margin(1.0 / 48000));
    REQUIRE(p.tracked);
    sq += (p.freq - truth(t - 500.0)) * (p.freq - truth(t - 500.0));
    ++n;
  }
  CHECK(std::sqrt(sq / n) <= 0.5);
  CHECK_FALSE(tracker.at(500.5).tracked);  // beyond the retained history
  CHECK_FALSE(tracker.at(504.5).tracked);  // its window is not complete yet
  CHECK_FALSE(tracker.at(NAN).tracked);
  const TrackPoint near = tracker.nearest(503.0 + 0.03);
  CHECK(near.tracked);
  CHECK(near.t == Approx(503.0).margin(1e-6));
  CHECK_FALSE(tracker.nearest(450.0).tracked);
}

TEST_CASE("tracker: a hole in the stream gives no output across it and tracking resumes") {
  const sim::FrequencyTrajectory truth = [](double) { return 130.0; };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  g.seed = 14;
  const auto x = sim::make_lighter_signal(g, truth, 6.0);
  SlidingDftTracker tracker(config_at(8000.0));
  const std::vector<float> a(x.begin(), x.begin() + 16000), b(x.begin() + 24000, x.end());
  auto points = track(tracker, a);
  tracker.skip(8000);  // one second lost
  TrackPoint last_before = points.back();
  const auto more = track(tracker, b);
  REQUIRE_FALSE(more.empty());
  CHECK(more.front().t >= 3.0 + 0.05);  // first window entirely after the hole
  CHECK(more.front().t > last_before.t);
  const Stats s = score(more, truth, 3.6, 6.0);
  CHECK(s.tracked_fraction >= 0.9);
  CHECK(s.rmse <= 0.5);
}

TEST_CASE("tracker: extract_channel picks one channel or mixes all") {
  const std::vector<float> stereo{1.0f, 3.0f, -2.0f, 4.0f, 5.0f, 5.0f};
  std::vector<float> out(8, 0.0f);
  CHECK(gearpulse::extract_channel(stereo, 2, 1, out) == 3);
  CHECK(out[0] == 3.0f);
  CHECK(out[2] == 5.0f);
  CHECK(gearpulse::extract_channel(stereo, 2, -1, out) == 3);
  CHECK(out[0] == 2.0f);
  CHECK(out[1] == 1.0f);
  CHECK(gearpulse::extract_channel(stereo, 2, 2, out) == 0);
  CHECK(gearpulse::extract_channel(stereo, 0, 0, out) == 0);
  std::vector<float> small(1);
  CHECK(gearpulse::extract_channel(stereo, 2, 0, small) == 1);
}

TEST_CASE("tracker: the fit of a window's orders solves the normal equations summed over the window") {
  constexpr double kRate = 1500.0;
  const int n = GENERATE(1, 3, 151, 241);
  INFO("window of " << n << " samples");
  const int mid = (n - 1) / 2;
  // A level, a slope, an idle's orders and a tone beside its fundamental, in pseudo-random noise.
  std::vector<double> y(static_cast<std::size_t>(n));
  std::uint32_t state = 12345;
  for (int j = 0; j < n; ++j) {
    state = state * 1664525u + 1013904223u;
    const double noise = static_cast<double>(state >> 8) / static_cast<double>(1u << 24) - 0.5;
    const double t = (j - mid) / kRate;
    y[static_cast<std::size_t>(j)] = 0.3 + 2.0 * t + std::sin(2.0 * std::numbers::pi * 27.0 * t + 0.4) +
                                     0.5 * std::cos(2.0 * std::numbers::pi * 54.2 * t) +
                                     0.2 * std::sin(2.0 * std::numbers::pi * 33.0 * t) + 0.1 * noise;
  }
  const double freq[gearpulse::SinusoidFit::kMaxSines] = {13.5, 27.0, 54.0, NAN, 33.0};
  // The reference: every column summed sample by sample, solved by Gaussian elimination.
  std::vector<std::vector<double>> column;
  column.emplace_back(static_cast<std::size_t>(n), 1.0);
  column.emplace_back(static_cast<std::size_t>(n));
  for (int j = 0; j < n; ++j)
    column[1][static_cast<std::size_t>(j)] = static_cast<double>(j - mid) / std::max(1, mid);
  for (const double f : freq) {
    if (!std::isfinite(f)) continue;
    std::vector<double> c(static_cast<std::size_t>(n)), s(static_cast<std::size_t>(n));
    for (int j = 0; j < n; ++j) {
      c[static_cast<std::size_t>(j)] = std::cos(2.0 * std::numbers::pi * f * (j - mid) / kRate);
      s[static_cast<std::size_t>(j)] = std::sin(2.0 * std::numbers::pi * f * (j - mid) / kRate);
    }
    column.push_back(c);
    column.push_back(s);
  }
  const std::size_t cols = column.size();
  std::vector<std::vector<double>> a(cols, std::vector<double>(cols + 1, 0.0));
  for (std::size_t r = 0; r < cols; ++r) {
    for (std::size_t c = 0; c < cols; ++c)
      for (int j = 0; j < n; ++j)
        a[r][c] += column[r][static_cast<std::size_t>(j)] * column[c][static_cast<std::size_t>(j)];
    for (int j = 0; j < n; ++j)
      a[r][cols] += column[r][static_cast<std::size_t>(j)] * y[static_cast<std::size_t>(j)];
  }
  const std::vector<std::vector<double>> normal = a;
  bool singular = false;
  for (std::size_t p = 0; p < cols && !singular; ++p) {
    std::size_t pivot = p;
    for (std::size_t r = p + 1; r < cols; ++r)
      if (std::abs(a[r][p]) > std::abs(a[pivot][p])) pivot = r;
    std::swap(a[p], a[pivot]);
    singular = !(std::abs(a[p][p]) > 1e-9 * std::abs(normal[p][p]));
    for (std::size_t r = 0; r < cols && !singular; ++r) {
      if (r == p) continue;
      const double k = a[r][p] / a[p][p];
      for (std::size_t c = p; c <= cols; ++c)
        a[r][c] -= k * a[p][c];
    }
  }
  gearpulse::SinusoidFit::Result fit;
  const double explained = gearpulse::SinusoidFit(n, kRate).fit(y.data(), freq, &fit);
  if (n < static_cast<int>(cols)) {  // fewer samples than columns: degenerate, explains nothing
    CHECK(explained == 0.0);
    return;
  }
  REQUIRE(!singular);
  REQUIRE(fit.cols == static_cast<int>(cols));
  double expected = 0.0;
  for (std::size_t r = 0; r < cols; ++r) {
    const double x = a[r][cols] / a[r][r];
    expected += x * normal[r][cols];
    CHECK(fit.coef[r] == Approx(x).epsilon(1e-8).margin(1e-9));
  }
  CHECK(explained == Approx(expected).epsilon(1e-10));
}
