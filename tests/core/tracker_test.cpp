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
#include <random>
#include <span>
#include <vector>

#include "core/sinusoid_fit.hpp"
#include "core/sliding_dft_tracker.hpp"
#include "core/tone_map.hpp"
#include "tests/alloc_counter.hpp"
#include "tools/sim/lighter_signal.hpp"
#include "tools/sim/lighter_signal_scene.hpp"

using gearpulse::SlidingDftTracker;
using gearpulse::TrackerConfig;
using gearpulse::TrackPoint;
namespace sim = gearpulse::sim;

using gearpulse::test::g_allocations;
using gearpulse::test::g_counting;

namespace {

// Feeds `x` in blocks of `block` frames (like a capture thread) and collects every output.
std::vector<TrackPoint> track(SlidingDftTracker& tracker, const std::vector<float>& x,
                              std::size_t block = 1024) {
  std::vector<TrackPoint> out;
  for (std::size_t at = 0; at < x.size(); at += block) {
    tracker.push(std::span<const float>(x).subspan(at, std::min(block, x.size() - at)));
    TrackPoint p;
    while (tracker.pop(p))
      out.push_back(p);
  }
  return out;
}

struct Stats {
  double rmse = 0.0;
  double max_error = 0.0;
  double tracked_fraction = 0.0;
  std::size_t considered = 0;
};

// Accuracy against the truth over hops with centre in [from, to].
Stats score(const std::vector<TrackPoint>& points, const sim::FrequencyTrajectory& truth, double from,
            double to) {
  Stats s;
  double sq = 0.0;
  std::size_t tracked = 0;
  for (const TrackPoint& p : points) {
    if (p.t < from || p.t > to) continue;
    ++s.considered;
    if (!p.tracked) continue;
    ++tracked;
    const double e = p.freq - truth(p.t);
    sq += e * e;
    s.max_error = std::max(s.max_error, std::abs(e));
  }
  s.rmse = tracked ? std::sqrt(sq / static_cast<double>(tracked)) : NAN;
  s.tracked_fraction = s.considered ? static_cast<double>(tracked) / static_cast<double>(s.considered) : 0.0;
  return s;
}

double tracked_fraction(const std::vector<TrackPoint>& points) {
  if (points.empty()) return 0.0;
  const auto n = std::count_if(points.begin(), points.end(), [](const TrackPoint& p) { return p.tracked; });
  return static_cast<double>(n) / static_cast<double>(points.size());
}

// Whether the window of length window_s centred at t holds a change of the engine's frequency faster than
// any ramp (a gear shift: the generated drives fall 30-40 % within 0.3 s, 100-200 Hz/s; ramps stay within
// the 60 Hz/s slew). Such a window smears the line over r T^2 resolution bins at rate r (170 Hz/s: 1.7
// bins at 0.1 s, 4.4 at 0.16 s), more than a 0 dB line's per-bin SNR survives, and the windows centred
// within (D + T) / 2 of a shift of duration D hold part of it: (D + T) / hop hops per shift, more for a
// longer window. Coverage at 0 dB is therefore asked of the hops whose window holds no shift.
bool window_holds_shift(const sim::FrequencyTrajectory& truth, double t, double window_s) {
  constexpr double kShiftHzPerS = 80.0, kStep = 0.005;
  for (double u = t - 0.5 * window_s; u <= t + 0.5 * window_s; u += kStep)
    if (std::abs(truth(u + 0.5 * kStep) - truth(u - 0.5 * kStep)) > kShiftHzPerS * kStep) return true;
  return false;
}

TrackerConfig config_at(double fs) {
  TrackerConfig c;
  c.sample_rate_hz = fs;
  return c;
}

}  // namespace

TEST_CASE("tracker: accurate on a ramping engine line at 5.1 8 44.1 and 48 kHz") {
  const double fs = GENERATE(5100.0, 8000.0, 44100.0, 48000.0);
  INFO("rate " << fs);
  const sim::FrequencyTrajectory truth = [](double t) { return 70.0 + 12.0 * t; };  // 70 -> 142 Hz
  sim::LighterSignalConfig g;
  g.sample_rate_hz = fs;
  g.snr_db = 10.0;
  g.seed = 3;
  SlidingDftTracker tracker(config_at(fs));
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 6.0));
  REQUIRE(points.size() >= 55);
  const Stats s = score(points, truth, 0.5, 6.0);
  CHECK(s.tracked_fraction >= 0.95);
  CHECK(s.rmse <= 0.5);  // bin width is 10 Hz
  CHECK(s.max_error <= 2.0);
}

// A clean ripple (a good sound card on a quiet supply) is 30-50 dB over the noise in the band. Such lines
// were once lost: their evidence, sampled on a grid coarser than a loud bin's likelihood, came out small,
// the line was learned as a fixed tone at its second window, and a missing half order cost as much as at
// the noise floor. Also at hops shorter than the window, and with no half order at all. With a 0.16 s
// window, whose line holds more power per bin, the shoulder term counted against noise alone took several
// nats from every state of the line and the track sat in "engine absent" (0-71 % tracked at short hops).
TEST_CASE("tracker: a clean line far above the noise is tracked") {
  const double fs = GENERATE(8000.0, 48000.0);
  const double snr = GENERATE(30.0, 40.0, 50.0);
  const double hop = GENERATE(0.1, 0.02);
  const double half = GENERATE(0.3, 0.0);
  const double window = GENERATE(0.1, 0.16);
  INFO("rate " << fs << " SNR " << snr << " dB hop " << hop << " s half order " << half << " window "
               << window << " s");
  const sim::FrequencyTrajectory truth = [](double t) {
    return 100.0 + 5.0 * std::sin(2.0 * std::numbers::pi * 0.3 * t);
  };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = fs;
  g.snr_db = snr;
  g.half_order = half;
  g.seed = 5;
  TrackerConfig c = config_at(fs);
  c.hop_s = hop;
  c.window_s = window;
  SlidingDftTracker tracker(c);
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 6.0));
  const Stats s = score(points, truth, 0.5, 6.0);
  CHECK(s.tracked_fraction >= 0.95);
  CHECK(s.rmse <= 0.5);
}

// A loud line without a half order that launches from idle: the ignition spikes give it a comb of
// harmonics, so the candidate at twice the fundamental finds its 2nd and 3rd orders on the 4th and 6th
// harmonics and its "half order" on the fundamental, while the fundamental pays for a half order it lacks.
// The tracker once locked on the 2nd harmonic at the launch (94 % of tracked hops wrong at 48 kHz, 40
// dB); it now learns from its confident, loud hops that this signal has no half order.
TEST_CASE("tracker: a loud launch with no half order is tracked on its fundamental, not its 2nd harmonic") {
  const double fs = GENERATE(8000.0, 48000.0);
  INFO("rate " << fs);
  const sim::FrequencyTrajectory truth = [](double t) {
    return t < 3.0 ? 40.0 : t < 9.0 ? 40.0 + 20.0 * (t - 3.0) : 160.0 + 4.0 * std::sin(t);
  };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = fs;
  g.snr_db = 40.0;
  g.half_order = 0.0;
  g.seed = 15;
  SlidingDftTracker tracker(config_at(fs));
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 20.0));
  std::size_t tracked = 0, wrong = 0;
  for (const TrackPoint& p : points) {
    if (p.t < 4.0 || !p.tracked) continue;
    ++tracked;
    wrong += std::abs(p.freq - truth(p.t)) > 0.05 * truth(p.t);
  }
  INFO(tracked << " hops tracked, " << wrong << " more than 5 % off");
  CHECK(tracked >= 80);  // of 160 in band
  CHECK(wrong <= tracked / 50);
}

// A clean line that idles below the band, launches, cruises, shifts and comes back to idle. Its idle
// orders stand still for seconds and the skirts of a line 40-50 dB over the noise spread over several
// resolution bins: both were learned as fixed tones, and within 20 s most of the band said nothing (half
// the hops or fewer tracked at 50 dB, with or without a half order). With a 0.16 s window the idle's
// comb (its ignition spikes give every harmonic) reaches the evidence's bound: the candidate at 4x the
// idle, whose ladder is the idle's 2nd, 4th, 8th and 12th harmonics, took the track (126 of 418 hops
// tracked at 8 kHz, 50 dB, no half order), and the comb's other lines, learned as tones during the idle,
// blanked the next launch's orders (325 of 418 at 40 dB).
TEST_CASE("tracker: a clean line through idles, launches and shifts is tracked all the way") {
  const double fs = GENERATE(8000.0, 48000.0);
  const double snr = GENERATE(40.0, 50.0);
  const double half = GENERATE(0.3, 0.0);
  const double window = GENERATE(0.1, 0.16);
  INFO("rate " << fs << " SNR " << snr << " dB half order " << half << " window " << window << " s");
  const sim::FrequencyTrajectory truth = [](double t) {
    const double cycle = std::fmod(t, 20.0);  // idle 3 s, launch, shift at 9 s, cruise, back to idle
    if (cycle < 3.0) return 38.0;
    if (cycle < 9.0) return 38.0 + 17.0 * (cycle - 3.0);
    if (cycle < 10.0) return 140.0 - 50.0 * (cycle - 9.0);
    if (cycle < 17.0) return 90.0 + 3.0 * std::sin(2.0 * cycle);
    return 90.0 - 17.0 * (cycle - 17.0);
  };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = fs;
  g.snr_db = snr;
  g.half_order = half;
  g.seed = 21;
  TrackerConfig c = config_at(fs);
  c.window_s = window;
  SlidingDftTracker tracker(c);
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 60.0));
  std::size_t in_band = 0, tracked = 0, wrong = 0;
  for (const TrackPoint& p : points) {
    const double f = truth(p.t);
    // Away from the band's edge and from the shift (and the windows that straddle it).
    if (p.t < 4.0 || f < 55.0 || std::abs(std::fmod(p.t, 20.0) - 9.5) < 0.6) continue;
    ++in_band;
    if (!p.tracked) continue;
    ++tracked;
    wrong += std::abs(p.freq - f) > 0.05 * f;
  }
  INFO(tracked << " of " << in_band << " hops tracked, " << wrong << " more than 5 % off");
  CHECK(tracked >= in_band * 95 / 100);
  CHECK(wrong <= tracked / 50);
}

// A clean drive (idle below the band, launches, shifts, cruises, stops) 50 dB over the noise, without a
// half order. Its idle's ignition comb stands still for seconds; with a 0.16 s window the comb's lines
// leave the noise floor clear between them, and the shoulders of each line's main lobe (one to two
// resolution bins from the harmonic, within 20 dB of it) were learned as fixed tones. On the next launch
// the engine's 2nd and 3rd orders crossed those tones and said nothing, a window's ratio fell from about
// 9.6 to 2.2 nats, and after each shift the track stayed in "engine absent" or on a wrong line for up to
// 1.5 s (71 % of in-band hops tracked at 8 kHz, 75 % at 48 kHz, against 100 % at 0.1 s).
TEST_CASE("tracker: a clean drive's idle comb is not learned as tones that blank its orders") {
  const double fs = GENERATE(8000.0, 48000.0);
  INFO("rate " << fs);
  constexpr double kSeconds = 60.0;
  const sim::FrequencyTrajectory truth = sim::drive_trajectory(kSeconds, 13);
  sim::LighterSignalConfig g;
  g.sample_rate_hz = fs;
  g.snr_db = 50.0;
  g.half_order = 0.0;
  g.seed = 13;
  const TrackerConfig c = config_at(fs);  // the default window, 0.16 s
  SlidingDftTracker tracker(c);
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, kSeconds));
  std::size_t in_band = 0, tracked = 0, wrong = 0;
  for (const TrackPoint& p : points) {
    const double f = truth(p.t);
    if (!(f >= c.band_lo_hz && f <= c.band_hi_hz)) continue;
    ++in_band;
    if (!p.tracked) continue;
    ++tracked;
    wrong += std::abs(p.freq - f) > 0.05 * f;
  }
  INFO(tracked << " of " << in_band << " in-band hops tracked, " << wrong << " more than 5 % off");
  REQUIRE(in_band >= 400);
  // The hops lost are those whose window holds part of a gear shift.
  CHECK(tracked >= in_band * 93 / 100);
  CHECK(wrong <= tracked / 100);
}

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

TEST_CASE("tracker: the harmonic ladder wins over a louder fixed tone") {
  const sim::FrequencyTrajectory truth = [](double t) { return 85.0 + 5.0 * std::sin(t); };
  sim::LighterSignalConfig g;
  g.snr_db = 10.0;
  g.tone_hz = 150.0;  // a fan, 6 dB louder than the engine's fundamental
  g.tone_amplitude = 2.0;
  g.seed = 5;
  SlidingDftTracker tracker(config_at(g.sample_rate_hz));
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 6.0));
  const Stats s = score(points, truth, 0.5, 6.0);
  CHECK(s.tracked_fraction >= 0.9);
  CHECK(s.max_error <= 2.0);
  for (const TrackPoint& p : points)
    if (p.tracked) CHECK(std::abs(p.freq - 150.0) > 20.0);
}

TEST_CASE("tracker: a fixed tone alone is not an engine") {
  sim::LighterSignalConfig g;
  g.snr_db = 10.0;
  g.tone_hz = 120.0;
  g.tone_amplitude = 2.0;
  g.seed = 6;
  SlidingDftTracker tracker(config_at(g.sample_rate_hz));
  const auto points = track(tracker, sim::make_lighter_signal(g, nullptr, 10.0));
  CHECK(points.size() >= 95);
  CHECK(tracked_fraction(points) <= 0.02);
}

TEST_CASE("tracker: frequency jumps are re-acquired") {
  // A gear shift as a step (harder than a real one): 150 Hz, then 95 Hz, then 140 Hz.
  const sim::FrequencyTrajectory truth = [](double t) { return t < 2.0 ? 150.0 : (t < 4.0 ? 95.0 : 140.0); };
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  g.snr_db = 10.0;
  g.seed = 7;
  SlidingDftTracker tracker(config_at(g.sample_rate_hz));
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 6.0));
  for (const double settle : {2.6, 4.6}) {
    const Stats s = score(points, truth, settle, settle + 1.3);
    INFO("after the jump at " << settle - 0.6 << " s");
    CHECK(s.tracked_fraction >= 0.9);
    CHECK(s.max_error <= 1.5);
  }
}

TEST_CASE("tracker: engine off and idle below the band are not tracked") {
  sim::LighterSignalConfig g;
  g.snr_db = 0.0;
  g.seed = 8;
  SECTION("noise only") {
    SlidingDftTracker tracker(config_at(g.sample_rate_hz));
    const auto points = track(tracker, sim::make_lighter_signal(g, nullptr, 10.0));
    CHECK(tracked_fraction(points) <= 0.02);
  }
  SECTION("idle at 40 Hz whose harmonics fall in the band") {
    g.snr_db = 15.0;
    SlidingDftTracker tracker(config_at(g.sample_rate_hz));
    const auto points = track(tracker, sim::make_lighter_signal(
                                           g, [](double) { return 40.0; }, 10.0));
    CHECK(tracked_fraction(points) <= 0.05);
  }
  SECTION("engine stops") {
    g.snr_db = 10.0;
    const sim::FrequencyTrajectory truth = [](double t) { return t < 3.0 ? 120.0 : NAN; };
    SlidingDftTracker tracker(config_at(g.sample_rate_hz));
    const auto points = track(tracker, sim::make_lighter_signal(g, truth, 7.0));
    CHECK(score(points, truth, 0.5, 2.9).tracked_fraction >= 0.9);
    std::size_t late = 0, after = 0;
    for (const TrackPoint& p : points) {
      if (p.t < 3.4) continue;
      ++after;
      late += p.tracked;
    }
    CHECK(after > 30);
    CHECK(late == 0);
  }
}

TEST_CASE("tracker: a band down to the idle with four periods of 25 Hz tracks an idle at 27 Hz") {
  sim::LighterSignalConfig g;
  g.snr_db = 10.0;
  g.seed = 8;
  const sim::FrequencyTrajectory truth = [](double) { return 27.0; };
  TrackerConfig c = config_at(g.sample_rate_hz);
  c.band_lo_hz = 25.0;
  c.window_s = 0.16;
  SlidingDftTracker tracker(c);
  const Stats s = score(track(tracker, sim::make_lighter_signal(g, truth, 10.0)), truth, 1.0, 9.5);
  INFO("tracked " << s.tracked_fraction << " of " << s.considered << " hops, largest error " << s.max_error
                  << " Hz");
  CHECK(s.tracked_fraction >= 0.9);
  CHECK(s.max_error <= 0.05 * 27.0);
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

TEST_CASE("tracker: reported SNR is unbiased against the generator from -5 to 20 dB") {
  const double fs = GENERATE(48000.0, 8000.0);
  const sim::FrequencyTrajectory truth = [](double t) { return 100.0 + 5.0 * t; };
  for (const double snr : {-5.0, 0.0, 10.0, 20.0}) {
    INFO("rate " << fs << " SNR " << snr << " dB");
    sim::LighterSignalConfig g;
    g.sample_rate_hz = fs;
    g.snr_db = snr;
    g.seed = 15;
    SlidingDftTracker tracker(config_at(fs));
    const auto points = track(tracker, sim::make_lighter_signal(g, truth, 8.0));
    // Every hop whose estimate is on the engine's line, tracked or not (no selection by confidence).
    std::vector<double> values;
    for (const TrackPoint& p : points)
      if (std::isfinite(p.freq) && std::abs(p.freq - truth(p.t)) <= 0.05 * truth(p.t))
        values.push_back(p.snr_db);
    REQUIRE(values.size() >= 40);
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2),
                     values.end());
    CHECK(values[values.size() / 2] == Approx(snr).margin(1.0));
  }
}

TEST_CASE("tracker: at -5 dB every hop gets an estimate and the confident ones are right") {
  const std::uint64_t seed = GENERATE(21, 22, 23);
  INFO("seed " << seed);
  const sim::FrequencyTrajectory truth = [](double t) { return 80.0 + 4.0 * t; };
  sim::LighterSignalConfig g;
  g.snr_db = -5.0;
  g.seed = seed;
  SlidingDftTracker tracker(config_at(g.sample_rate_hz));
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 10.0));
  std::size_t hops = 0, valued = 0, right = 0, confident = 0, confident_right = 0;
  double confidence = 0.0;
  for (const TrackPoint& p : points) {
    if (p.t < 1.0) continue;
    ++hops;
    if (!std::isfinite(p.freq)) {
      CHECK_FALSE(p.tracked);
      CHECK(p.confidence == 0.0);
      continue;
    }
    CHECK(p.confidence >= 0.0);
    CHECK(p.confidence <= 1.0);
    CHECK(p.tracked == (p.confidence >= 0.8));
    const bool ok = std::abs(p.freq - truth(p.t)) <= 0.05 * truth(p.t);
    ++valued;
    right += ok;
    confidence += p.confidence;
    if (p.confidence >= 0.8) {
      ++confident;
      confident_right += ok;
    }
  }
  REQUIRE(hops >= 85);
  CHECK(valued >= 0.9 * static_cast<double>(hops));  // a flagged value rather than nothing
  CHECK(right >= 0.65 * static_cast<double>(valued));
  // The confidence does not promise more than it delivers, and a confident hop is right.
  CHECK(confidence / static_cast<double>(valued) <=
        static_cast<double>(right) / static_cast<double>(valued) + 0.1);
  REQUIRE(confident >= 5);
  CHECK(confident_right >= 0.85 * static_cast<double>(confident));
}

TEST_CASE("tracker: confidence is calibrated on a 0 dB drive with shifts and stops") {
  const std::uint64_t seed = GENERATE(21, 22);
  const double window = GENERATE(0.1, 0.16);
  INFO("seed " << seed << " window " << window << " s");
  const auto truth = sim::drive_trajectory(60.0, seed);
  sim::LighterSignalConfig g;
  g.snr_db = 0.0;
  g.seed = seed;
  TrackerConfig c = config_at(g.sample_rate_hz);
  c.window_s = window;
  SlidingDftTracker tracker(c);
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 60.0));
  std::size_t in_band = 0, valued = 0, right = 0, tracked = 0, tracked_right = 0, clear = 0,
              clear_tracked = 0;
  double confidence = 0.0;
  for (const TrackPoint& p : points) {
    const double f = truth(p.t);
    if (!(f >= 50.0 && f <= 200.0)) continue;
    ++in_band;
    if (!window_holds_shift(truth, p.t, tracker.config().window_s)) {
      ++clear;
      clear_tracked += p.tracked;
    }
    if (!std::isfinite(p.freq)) continue;
    const bool ok = std::abs(p.freq - f) <= 0.05 * f;
    ++valued;
    right += ok;
    confidence += p.confidence;
    tracked += p.tracked;
    tracked_right += p.tracked && ok;
  }
  INFO(tracked << " of " << in_band << " in-band hops tracked, " << clear_tracked << " of the " << clear
               << " whose window holds no shift");
  REQUIRE(in_band >= 400);
  REQUIRE(clear >= 0.85 * static_cast<double>(in_band));
  CHECK(clear_tracked >= 0.97 * static_cast<double>(clear));
  CHECK(tracked_right >= 0.99 * static_cast<double>(tracked));
  CHECK(confidence / static_cast<double>(valued) ==
        Approx(static_cast<double>(right) / static_cast<double>(valued)).margin(0.05));
}

TEST_CASE("tracker: a fan the engine line crosses is learned and does not capture the track") {
  // The fan runs all along, as loud as the engine's fundamental; the engine starts after 8 s and
  // ramps through the fan's frequency.
  const sim::FrequencyTrajectory truth = [](double t) { return t < 8.0 ? NAN : 100.0 + 5.0 * (t - 8.0); };
  sim::LighterSignalConfig g;
  g.snr_db = 10.0;
  g.tone_hz = 137.0;
  g.tone_amplitude = 1.0;
  g.seed = GENERATE(21, 22);
  SlidingDftTracker tracker(config_at(g.sample_rate_hz));
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 22.0));
  std::size_t fan_only = 0, fan_tracked = 0;
  for (const TrackPoint& p : points)
    if (p.t >= 4.0 && p.t < 7.8) {
      ++fan_only;
      fan_tracked += p.tracked;
    }
  CHECK(fan_only >= 30);
  CHECK(fan_tracked <= 2);
  const Stats s = score(points, truth, 9.0, 21.9);
  CHECK(s.tracked_fraction >= 0.9);
  CHECK(s.max_error <= 3.0);
}

TEST_CASE("tracker: a 2nd harmonic louder than the fundamental still gives the fundamental") {
  const sim::FrequencyTrajectory truth = [](double t) { return 60.0 + 8.0 * t; };
  sim::LighterSignalConfig g;
  g.snr_db = 10.0;
  g.harmonic2 = 1.3;
  g.seed = GENERATE(21, 22);
  SlidingDftTracker tracker(config_at(g.sample_rate_hz));
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 10.0));
  const Stats s = score(points, truth, 0.5, 10.0);
  CHECK(s.tracked_fraction >= 0.9);
  CHECK(s.rmse <= 0.5);
  CHECK(s.max_error <= 1.5);
}

// An engine that accelerates under load (the fundamental leads) and then brakes on the overrun, where
// the 2nd harmonic takes the fundamental's energy and stands up to 12 dB over it. Read under the
// harmonics' usual prior (at most +3 dB) the candidate at twice the fundamental, whose "half order" is
// the fundamental, explained the overrun better, and the track sat on the 2nd harmonic for seconds. No
// tracked hop may stay on twice the fundamental longer than 0.3 s.
TEST_CASE("tracker: a 2nd harmonic that takes over on the overrun does not hold the track at twice it") {
  const double snr = GENERATE(10.0, 0.0);
  const std::uint64_t seed = GENERATE(31, 32);
  INFO("snr " << snr << " dB, seed " << seed);
  const sim::FrequencyTrajectory truth = [](double t) {
    return t < 2.0 ? 70.0 : t < 6.0 ? 70.0 + 20.0 * (t - 2.0) : t < 14.0 ? 150.0 - 10.0 * (t - 6.0) : 70.0;
  };
  sim::LighterSceneConfig c;
  c.harmonic2 = 1.6;
  c.load_swing = 0.6;
  c.load_slew_hz_per_s = 10.0;  // the braking at -10 Hz/s is a full overrun
  c.alternator = c.body = c.fan = c.pump = c.mains = 0.0;
  c.agc_s = 0.0;
  c.clip = 1e9;
  c.snr_db = snr;
  c.seed = seed;
  SlidingDftTracker tracker(config_at(c.sample_rate_hz));
  const auto points = track(tracker, sim::make_lighter_scene(c, truth, 16.0));
  std::size_t tracked = 0, at_double = 0, run = 0, longest = 0;
  for (const TrackPoint& p : points) {
    if (p.t < 0.5) continue;
    const bool doubled = p.tracked && std::abs(p.freq - 2.0 * truth(p.t)) <= 0.1 * truth(p.t);
    tracked += p.tracked;
    at_double += doubled;
    run = doubled ? run + 1 : 0;
    longest = std::max(longest, run);
  }
  INFO(tracked << " hops tracked, " << at_double << " at twice the fundamental, longest run " << longest);
  CHECK(tracked >= 100);  // of 155
  CHECK(at_double <= tracked / 50);
  CHECK(static_cast<double>(longest) * tracker.config().hop_s <= 0.3 + 1e-9);
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

TEST_CASE("tracker: a 0 dB drive at 8 kHz keeps no confident old line through its gear shifts") {
  // A generated drive (shifts fall 30-40 % within 0.3 s) at 0 dB. In a window a shift sweeps through, the
  // line's power is smeared over two resolution bins beside where the track held it; the old line must
  // not be reported with confidence, and the sub-bin fit must stay on the line elsewhere.
  const double window = GENERATE(0.1, 0.16);
  INFO("window " << window << " s");
  const sim::FrequencyTrajectory truth = sim::drive_trajectory(120.0, 12);
  sim::LighterSignalConfig g;
  g.sample_rate_hz = 8000.0;
  g.snr_db = 0.0;
  g.seed = 12;
  TrackerConfig c = config_at(g.sample_rate_hz);
  c.window_s = window;
  SlidingDftTracker tracker(c);
  const auto points = track(tracker, sim::make_lighter_signal(g, truth, 120.0));
  std::size_t in_band = 0, tracked = 0, wrong = 0, clear = 0, clear_tracked = 0;
  double sq = 0.0;
  for (const TrackPoint& p : points) {
    const double f = truth(p.t);
    if (!(f >= 50.0 && f <= 200.0)) continue;
    ++in_band;
    if (!window_holds_shift(truth, p.t, tracker.config().window_s)) {
      ++clear;
      clear_tracked += p.tracked;
    }
    if (!p.tracked) continue;
    ++tracked;
    sq += (p.freq - f) * (p.freq - f);
    if (std::abs(p.freq - f) > 0.05 * f) {
      ++wrong;
      UNSCOPED_INFO("t " << p.t << " truth " << f << " reported " << p.freq << " confidence "
                         << p.confidence);
    }
  }
  INFO(tracked << " of " << in_band << " in-band hops tracked, " << clear_tracked << " of the " << clear
               << " whose window holds no shift");
  REQUIRE(in_band >= 900);
  REQUIRE(clear >= 0.85 * static_cast<double>(in_band));
  CHECK(static_cast<double>(clear_tracked) >= 0.97 * static_cast<double>(clear));
  CHECK(wrong <= 1);
  CHECK(std::sqrt(sq / static_cast<double>(tracked)) <= 0.8);
}

namespace {

// The track points and the true line of a 120 s scene of the generated sets (launches, shifts, overruns,
// a cabin's other lines) at `snr_db`.
struct ScenePoints {
  sim::FrequencyTrajectory truth;
  std::vector<TrackPoint> points;
};
ScenePoints track_scene(std::uint64_t seed, double snr_db) {
  constexpr double kDurationS = 120.0;
  sim::FrequencyTrajectory truth = sim::launch_drive_trajectory(kDurationS, seed);
  const sim::LighterSceneConfig c = sim::scene_for_seed(seed, snr_db);
  SlidingDftTracker tracker(config_at(c.sample_rate_hz));
  auto points = track(tracker, sim::make_lighter_scene(c, truth, kDurationS));
  return {std::move(truth), std::move(points)};
}

// The true line's rate of change at `t` (Hz/s).
double rate_at(const sim::FrequencyTrajectory& truth, double t) {
  return (truth(t + 0.1) - truth(t - 0.1)) / 0.2;
}

// Of a scene's in-band hops (50-200 Hz) those `keep` selects by their time, how many are tracked and how
// many tracked ones are more than 5 % off the line.
struct HopCounts {
  std::size_t selected = 0, tracked = 0, wrong = 0;
};
template <class Keep>
HopCounts count_hops(const ScenePoints& scene, Keep keep) {
  HopCounts n;
  for (const TrackPoint& p : scene.points) {
    const double f = scene.truth(p.t);
    if (!(f >= 50.0 && f <= 200.0) || !keep(p.t)) continue;
    ++n.selected;
    if (!p.tracked) continue;
    ++n.tracked;
    n.wrong += std::abs(p.freq - f) > 0.05 * f;
  }
  return n;
}

// Of a scene's in-band hops, how many are tracked, how many tracked within 5 % of `multiple` times the
// engine, and the longest run of those (a run is in time: an out-of-band stretch ends it).
struct MultipleCounts {
  std::size_t in_band = 0, tracked = 0, there = 0, longest = 0;
};
MultipleCounts count_at_multiple(const ScenePoints& scene, double multiple) {
  MultipleCounts n;
  std::size_t run = 0;
  for (const TrackPoint& p : scene.points) {
    const double f = scene.truth(p.t);
    if (!(f >= 50.0 && f <= 200.0)) {
      run = 0;
      continue;
    }
    ++n.in_band;
    const bool there = p.tracked && std::abs(p.freq - multiple * f) <= 0.05 * (multiple * f);
    n.tracked += p.tracked;
    n.there += there;
    run = there ? run + 1 : 0;
    n.longest = std::max(n.longest, run);
  }
  return n;
}

}  // namespace

// A -5 dB scene of the generated tuning set (launches, shifts, overruns, a cabin's other lines): the
// engine's line fades from window to window, and a track that passed to "engine absent" on every faded
// window restarted anywhere, often on twice the engine. The track keeps its line through faded windows:
// it covers a third of the in-band hops, and its tracked hops are right.
TEST_CASE("tracker: a -5 dB scene is tracked through faded windows") {
  const std::uint64_t seed = GENERATE(101, 106);
  INFO("seed " << seed);
  const auto [in_band, tracked, wrong] = count_hops(track_scene(seed, -5.0), [](double) { return true; });
  INFO(in_band << " in-band hops, " << tracked << " tracked, " << wrong << " of them wrong");
  REQUIRE(in_band >= 800);
  CHECK(static_cast<double>(tracked) >= 0.33 * static_cast<double>(in_band));
  CHECK(static_cast<double>(wrong) <= 0.03 * static_cast<double>(tracked));
}

// After a shift at -5 dB the posterior reaches 0.8 on the new line a second or two after its estimates are
// right. Decided half a second later, a hop whose line the next hops continue takes the latest hop's
// confidence: every estimate and time stay the hop's own, no confidence falls, and on seed 102 the hops
// within 2 s of a shift or launch are tracked 12 points more often (62 -> 74 %; the tuning set's at -5 dB:
// 49 -> 62 %), the hops added right as a rule. The outputs at once (the live speed's) are those without
// the lag, delivered as soon.
TEST_CASE("tracker: a fixed-lag decision tracks the hops after a shift whose line the next hops continue") {
  constexpr std::uint64_t kSeed = 102;
  constexpr double kDurationS = 120.0;
  const sim::FrequencyTrajectory truth = sim::launch_drive_trajectory(kDurationS, kSeed);
  const sim::LighterSceneConfig scene = sim::scene_for_seed(kSeed, -5.0);
  const std::vector<float> x = sim::make_lighter_scene(scene, truth, kDurationS);
  std::vector<TrackPoint> live;  // the lagged run's outputs at once
  const auto run = [&](double lag) {
    TrackerConfig c = config_at(scene.sample_rate_hz);
    c.decision_lag_s = lag;
    SlidingDftTracker tracker(c);
    std::vector<TrackPoint> points;
    live.clear();
    TrackPoint p;
    for (std::size_t at = 0; at < x.size(); at += 1024) {
      tracker.push(std::span<const float>(x).subspan(at, std::min<std::size_t>(1024, x.size() - at)));
      while (tracker.pop(p))
        live.push_back(p);
      while (tracker.pop_decided(p))
        points.push_back(p);
      // Held back by the lag (rounded to whole hops) only in the decided queue; the history that at() and
      // nearest() read takes each hop's decided confidence.
      const auto held = static_cast<std::size_t>(std::lround(lag / c.hop_s));
      CHECK(live.size() - points.size() == std::min(live.size(), held));
      if (!points.empty()) CHECK(tracker.nearest(points.back().t).confidence == points.back().confidence);
    }
    tracker.finish();
    while (tracker.pop_decided(p))
      points.push_back(p);
    CHECK_FALSE(tracker.pop(p));
    return points;
  };
  const std::vector<TrackPoint> now = run(0.0), later = run(0.5);
  REQUIRE(later.size() == now.size());
  REQUIRE(live.size() == now.size());
  for (std::size_t i = 0; i < now.size(); ++i) {
    CHECK(live[i].t == now[i].t);
    CHECK((live[i].freq == now[i].freq || (std::isnan(live[i].freq) && std::isnan(now[i].freq))));
    CHECK(live[i].confidence == now[i].confidence);
  }
  // Within 2 s of a shift (the truth moving faster than 60 Hz/s over 0.2 s) or of the line's entry.
  const auto after_shift = [&](double t) {
    for (double s = 0.0; s <= 2.0; s += 0.05) {
      const double a = truth(t - s), b = truth(t - s - 0.2);
      if (!(a >= 50.0 && a <= 200.0) || !std::isfinite(b) || std::abs(a - b) > 12.0) return true;
    }
    return false;
  };
  std::size_t hops = 0, tracked_now = 0, tracked_later = 0, wrong_now = 0, wrong_later = 0;
  for (std::size_t i = 0; i < now.size(); ++i) {
    REQUIRE(later[i].t == now[i].t);
    CHECK((later[i].freq == now[i].freq || (std::isnan(later[i].freq) && std::isnan(now[i].freq))));
    CHECK(later[i].confidence >= now[i].confidence);
    const double f = truth(now[i].t);
    if (!(f >= 50.0 && f <= 200.0) || !after_shift(now[i].t)) continue;
    ++hops;
    tracked_now += now[i].tracked;
    tracked_later += later[i].tracked;
    wrong_now += now[i].tracked && std::abs(now[i].freq - f) > 0.05 * f;
    wrong_later += later[i].tracked && std::abs(later[i].freq - f) > 0.05 * f;
  }
  INFO(hops << " hops within 2 s of a shift or entry: " << tracked_now << " tracked at once (" << wrong_now
            << " wrong), " << tracked_later << " decided 0.5 s later (" << wrong_later << " wrong)");
  REQUIRE(hops >= 200);
  CHECK(static_cast<double>(tracked_later) >=
        static_cast<double>(tracked_now) + 0.08 * static_cast<double>(hops));
  // The hops the later windows confirm are right: at most one in eight of those added is wrong (4 of 40).
  CHECK(wrong_later <= wrong_now + (tracked_later - tracked_now) / 8);
}

// A launch ramps at up to 50 Hz/s: at -5 dB a track whose prior stays where the line was loses the line's
// place on every hop of a ramp. The line's rate of change is a state of the track, so a ramp is followed as
// a cruise is: on seeds 102 and 106 the rising hops are tracked 70 and 80 % of the time (a prior without
// the rate tracks 50 and 55 %); 65 % lies between the two.
TEST_CASE("tracker: at -5 dB a launch's ramps are followed at their rate") {
  const std::uint64_t seed = GENERATE(102, 106);
  INFO("seed " << seed);
  const ScenePoints scene = track_scene(seed, -5.0);
  const auto [rising, tracked, wrong] =
      count_hops(scene, [&](double t) { return rate_at(scene.truth, t) > 8.0; });
  INFO(rising << " rising in-band hops, " << tracked << " tracked, " << wrong << " of them wrong");
  REQUIRE(rising >= 250);
  CHECK(static_cast<double>(tracked) >= 0.65 * static_cast<double>(rising));
  CHECK(static_cast<double>(wrong) <= 0.03 * static_cast<double>(tracked));
}

// Engine braking hands the firing line's energy to its 2nd harmonic (the scenes' overrun puts it up to
// 15 dB over a fundamental that fades): under the usual level prior, where a loud 2nd harmonic costs
// ln 0.15, the engine's line then scored little more than "engine absent" and its falling hops were refused.
// A line falling at 20 Hz/s or faster reads the 2nd harmonic as loud half of the time. On seeds 103 and 104
// at -5 dB the falling hops are tracked 77 and 75 % of the time (67 and 66 % with the usual prior
// throughout); 72 % lies between.
TEST_CASE("tracker: at -5 dB engine braking is tracked through its loud 2nd harmonic") {
  const std::uint64_t seed = GENERATE(103, 104);
  INFO("seed " << seed);
  const ScenePoints scene = track_scene(seed, -5.0);
  const auto [falling, tracked, wrong] =
      count_hops(scene, [&](double t) { return rate_at(scene.truth, t) < -8.0; });
  INFO(falling << " falling in-band hops, " << tracked << " tracked, " << wrong << " of them wrong");
  REQUIRE(falling >= 250);
  CHECK(static_cast<double>(tracked) >= 0.72 * static_cast<double>(falling));
  CHECK(static_cast<double>(wrong) <= 0.03 * static_cast<double>(tracked));
}

// Engine braking slower than the overrun's 20 Hz/s lightens the load too: the fundamental fades (down to a
// third of its level on the scenes) while the 2nd harmonic grows. A candidate's other orders are scaled by
// its fundamental's level, read from its own bin; at -5 dB one window's reading of a faded line lies
// anywhere from the noise to twice its level, and scaled by a low reading the loud 2nd harmonic was judged
// louder than the prior allows. Averaged over the reading's scatter, the hops falling at 8-20 Hz/s of scenes
// 104 and 105 at -5 dB are tracked 408 of 524 times (387 with the reading taken as the level; 76 % lies
// between).
TEST_CASE("tracker: at -5 dB slow engine braking is tracked where its fundamental fades") {
  std::size_t falling = 0, tracked = 0, wrong = 0;
  for (const std::uint64_t seed : {std::uint64_t{104}, std::uint64_t{105}}) {
    const ScenePoints scene = track_scene(seed, -5.0);
    const HopCounts n = count_hops(scene, [&](double t) {
      const double rate = rate_at(scene.truth, t);
      return rate > -20.0 && rate < -8.0;
    });
    falling += n.selected;
    tracked += n.tracked;
    wrong += n.wrong;
  }
  INFO(falling << " in-band hops falling at 8-20 Hz/s, " << tracked << " tracked, " << wrong
               << " of them wrong");
  REQUIRE(falling >= 450);
  CHECK(static_cast<double>(tracked) >= 0.76 * static_cast<double>(falling));
  CHECK(static_cast<double>(wrong) <= 0.03 * static_cast<double>(tracked));
}

// A candidate at two thirds of the engine reads its 2nd harmonic as a 3rd harmonic as loud as its own
// fundamental, which the fixed prior of the 3rd harmonic's level (-13 to +3 dB) allows; this scene's engine
// has a 3rd harmonic about 12 dB under its fundamental, which the track learns while it is confident and
// loud. Scene 305 at 10 dB: without the learned level 6.8 % of the tracked in-band hops sit at two thirds of
// the engine, in runs of up to 2.4 s; with it 0.4 %, none longer than 0.3 s.
TEST_CASE("tracker: the learned level of the 3rd harmonic keeps the track off two thirds of the engine") {
  const auto [in_band, tracked, at_two_thirds, longest] =
      count_at_multiple(track_scene(305, 10.0), 2.0 / 3.0);
  INFO(in_band << " in-band hops, " << tracked << " tracked, " << at_two_thirds
               << " at two thirds of the engine, longest run " << longest << " hops");
  REQUIRE(in_band >= 800);
  CHECK(static_cast<double>(tracked) >= 0.85 * static_cast<double>(in_band));
  CHECK(static_cast<double>(at_two_thirds) <= 0.02 * static_cast<double>(tracked));
  CHECK(longest <= 5);
}

// A launch rises at 35-50 Hz/s, under power, where the fundamental takes the firing energy and its 2nd
// harmonic stands below it. A candidate at half the engine reads the engine's line as its own 2nd harmonic,
// 9-17 dB over its fundamental (the scene's half order), and the launch's higher orders smear over more
// resolution bins than its lower ones; with a loud 2nd harmonic as likely under power as at a cruise, the
// track followed half the engine through launches from idle. Scenes 105 at 10 dB and 101 at 0 dB: 3 and 4
// tracked hops at half the engine with the loud 2nd harmonic's share of a cruise on rising layers; 0 and 2
// with the share under power.
TEST_CASE("tracker: a launch under power is not tracked at half the engine") {
  std::size_t in_band = 0, halved = 0;
  for (const auto& [seed, snr] : {std::pair<std::uint64_t, double>{105, 10.0}, {101, 0.0}}) {
    const MultipleCounts n = count_at_multiple(track_scene(seed, snr), 0.5);
    in_band += n.in_band;
    halved += n.there;
  }
  INFO(in_band << " in-band hops, " << halved << " tracked at half the engine");
  REQUIRE(in_band >= 1600);
  CHECK(halved <= 3);
}

// An upshift's windows smear the line and the track loses it; the new gear, at light load, shows a loud 2nd
// harmonic at about 1.3 times the line before the shift. A rising line's shift is an upshift, whose revs
// fall by the gear step, so the track is found again below, not on that 2nd harmonic. Scenes 101 and 104 at
// -5 dB: with a shift that reaches either way from a rising line, 16 and 15 tracked hops sat at twice the
// engine after upshifts, in runs of up to 11 and 15 hops; with its shift reaching below only, 3 and 0,
// in runs of at most 3 (0.3 s).
TEST_CASE("tracker: after an upshift at -5 dB the track is not held at twice the engine") {
  const std::uint64_t seed = GENERATE(101, 104);
  INFO("seed " << seed);
  const auto [in_band, tracked, doubled, longest] = count_at_multiple(track_scene(seed, -5.0), 2.0);
  INFO(in_band << " in-band hops, " << tracked << " tracked, " << doubled
               << " at twice the engine, longest run " << longest << " hops");
  REQUIRE(in_band >= 800);
  CHECK(longest <= 3);
  CHECK(static_cast<double>(doubled) <= 0.01 * static_cast<double>(tracked));
}

// Scene 104's body resonance (35 Hz, Q 6.5, three times the fundamental's RMS) raises the lower quartile of
// the noise floor's first block (25-100 Hz), and the floor over the band reads 1.3-1.5 times its noise: at
// -5 dB the engine's line then loses 1.5 dB in every window. Scaled back by each bin's long-run level below
// the floor, 83 % of its in-band hops are tracked (77 % with the floor as read); 80 % lies between.
TEST_CASE("tracker: at -5 dB a body resonance below the band does not lower the band's evidence") {
  const auto [in_band, tracked, wrong] = count_hops(track_scene(104, -5.0), [](double) { return true; });
  INFO(in_band << " in-band hops, " << tracked << " tracked, " << wrong << " of them wrong");
  REQUIRE(in_band >= 800);
  CHECK(static_cast<double>(tracked) >= 0.80 * static_cast<double>(in_band));
  CHECK(static_cast<double>(wrong) <= 0.02 * static_cast<double>(tracked));
}

// A window's noise floor is the lower quartile of blocks of 75 Hz; a block that holds a body resonance's
// skirt or lines of other equipment reads above the noise of its quieter bins. Lines only add power, so a
// bin whose readings over the floor average below 1 stands under its floor, and its readings are divided by
// that average (down to 0.5): the bins of a floor read 1.7 times the noise (mean 0.6) read as noise again,
// those on the floor (mean 1) as before.
TEST_CASE("tone map: a bin that reads below the noise floor on average is scaled back to it") {
  constexpr std::size_t kBins = 256;
  gearpulse::ToneMap tones(kBins, 8, 240, 8, 0.4, 0.1);
  std::mt19937_64 rng(5);
  std::exponential_distribution<double> noise(1.0);
  std::vector<double> power(kBins), floor(kBins, 1.0);
  const double order[] = {1.0};
  for (int hop = 0; hop < 600; ++hop) {  // 60 s, three memories
    for (std::size_t k = 0; k < kBins; ++k)
      power[k] = (k < 128 ? 0.6 : 1.0) * noise(rng);
    tones.learn(power.data(), floor.data(), NAN, order, false, false);
  }
  for (const std::size_t k : {40, 100}) {
    INFO("bin " << k);
    CHECK(tones.background(k) == Approx(0.6).epsilon(0.15));
  }
  for (const std::size_t k : {150, 220}) {
    INFO("bin " << k);
    CHECK(tones.background(k) == Approx(1.0).epsilon(0.15));
  }
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
