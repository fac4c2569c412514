// The tracker on the generated scenes (launches, shifts, overruns, a cabin's other lines), most at -5 dB:
// faded windows, the fixed-lag decision, ramps, engine braking, the track kept off multiples of the engine
// (a run-up at 30 dB among them), and the noise floor under a body resonance.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <random>
#include <span>
#include <utility>
#include <vector>

#include "core/sliding_dft_tracker.hpp"
#include "core/tone_map.hpp"
#include "tests/core/tracker_run.hpp"
#include "tools/sim/lighter_signal.hpp"
#include "tools/sim/lighter_signal_scene.hpp"

using gearpulse::SlidingDftTracker;
using gearpulse::TrackerConfig;
using gearpulse::TrackPoint;
namespace sim = gearpulse::sim;
using namespace gearpulse::test::tracker_run;

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

// A run-up at full throttle at 30 dB (scene 104's levels and lines, 970 -> 4,820 rpm over 16 s): the band's
// floor is held 25 dB over the white noise by the crowd of lines in it, while above the band only the
// ignition spikes' comb stands, 25-29 dB under the fundamental. Read as per-bin SNRs, the comb's lines at
// 4 f and 6 f stood as loud as the fundamental, and the state at twice the engine (its half order the
// engine's line) held the track for 3.9 s (39 hops). Read as power ratios, carried through the two floors,
// they are what they are, and the track stays on the engine.
TEST_CASE("tracker: a run-up at 30 dB is not held at twice the engine") {
  constexpr double kRampS = 16.0;
  const double duration = sim::run_up_duration(kRampS);
  ScenePoints scene{sim::run_up_trajectory(kRampS), {}};
  const sim::LighterSceneConfig c = sim::run_up_scene_for_seed(104, 30.0, kRampS);
  SlidingDftTracker tracker(config_at(c.sample_rate_hz));
  scene.points = track(tracker, sim::make_lighter_scene(c, scene.truth, duration));
  const auto [in_band, tracked, doubled, longest] = count_at_multiple(scene, 2.0);
  INFO(in_band << " in-band hops, " << tracked << " tracked, " << doubled
               << " at twice the engine, longest run " << longest << " hops");
  REQUIRE(in_band >= 120);
  CHECK(longest <= 3);
  CHECK(static_cast<double>(tracked) >= 0.9 * static_cast<double>(in_band));
}

// A run-up at 30 dB (scene 106's levels and lines, 970 -> 4,820 rpm over 20 s): as the engine comes up
// through 43-53 Hz its fundamental lies under the tones learned in the band's lowest part, and the state at
// three times it reads its 2nd and 3rd orders (the comb's 6th and 9th, 260-480 Hz) above the band, where
// the floor is the white noise's and they reach the evidence's bound. The 3rd root's bins 4 f / 3 and
// 5 f / 3 (the comb's 4th and 5th) lay in the band or at its top, where the crowd's floor stands over the
// comb, and read background: the track held three times the engine for 2.6 s (26 hops). The 3rd root is
// also judged at 8 f / 3, the comb's 8th, between the state's own 2nd and 3rd orders.
TEST_CASE("tracker: a run-up at 30 dB is not held at three times the engine") {
  constexpr double kRampS = 20.0;
  const double duration = sim::run_up_duration(kRampS);
  ScenePoints scene{sim::run_up_trajectory(kRampS), {}};
  const sim::LighterSceneConfig c = sim::run_up_scene_for_seed(106, 30.0, kRampS);
  SlidingDftTracker tracker(config_at(c.sample_rate_hz));
  scene.points = track(tracker, sim::make_lighter_scene(c, scene.truth, duration));
  const auto [in_band, tracked, tripled, longest] = count_at_multiple(scene, 3.0);
  INFO(in_band << " in-band hops, " << tracked << " tracked, " << tripled
               << " at three times the engine, longest run " << longest << " hops");
  REQUIRE(in_band >= 150);
  CHECK(longest <= 3);
  CHECK(static_cast<double>(tracked) >= 0.9 * static_cast<double>(in_band));
}

// An engine whose ignition spikes give every harmonic shows at twice and three times its frequency a full
// ladder of the comb's lines, and at high SNR those ladders reach the evidence's bound as the engine's own
// does. A candidate there is judged as the 2nd and 3rd multiple of a lower engine (the lower engine's 5th
// and 7th orders at 5 f / 2 and 7 f / 2, its 4th and 5th at 4 f / 3 and 5 f / 3): on scene 103 at 30 dB,
// with its coast-downs, no run at twice or three times the engine lasts beyond 0.3 s
// (docs/algorithms/tracker-experiments.md gives the figures).
TEST_CASE("tracker: at 30 dB a comb's 2nd and 3rd multiples do not hold the track") {
  const ScenePoints scene = track_scene(103, 30.0);
  for (const double multiple : {2.0, 3.0}) {
    const auto [in_band, tracked, there, longest] = count_at_multiple(scene, multiple);
    INFO(in_band << " in-band hops, " << tracked << " tracked, " << there << " at " << multiple
                 << " times the engine, longest run " << longest << " hops");
    REQUIRE(in_band >= 800);
    CHECK(static_cast<double>(tracked) >= 0.9 * static_cast<double>(in_band));
    CHECK(longest <= 3);
    CHECK(static_cast<double>(there) <= 0.003 * static_cast<double>(tracked));
  }
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

namespace {

// A tone map after 60 s of hops (0.4 Hz fine bins) whose estimate, tracked, lies at fine bin `estimate`, over
// unit noise with `lines` (fine bin, power in noise units) standing still.
gearpulse::ToneMap tones_learned(std::size_t estimate,
                                 std::initializer_list<std::pair<std::size_t, double>> lines) {
  constexpr std::size_t kBins = 256;
  constexpr double kDf = 0.4;
  const double orders[] = {0.5, 1.0, 2.0, 3.0};
  gearpulse::ToneMap tones(kBins, 8, 240, 8, kDf, 0.1);
  std::mt19937_64 rng(7);
  std::exponential_distribution<double> noise(1.0);
  std::vector<double> power(kBins), floor(kBins, 1.0);
  for (int hop = 0; hop < 600; ++hop) {
    for (std::size_t k = 0; k < kBins; ++k)
      power[k] = noise(rng);
    for (const auto& [k, p] : lines)
      power[k] += p;
    tones.learn(power.data(), floor.data(), static_cast<double>(estimate) * kDf, orders, true, false);
  }
  return tones;
}

// One line over exponential noise fed to a tone map (a resolution bin of 3.2 Hz) off the track, the
// estimate ramped from `from_hz` to `to_hz` over the hops.
struct LineFeed {
  static constexpr std::size_t kBins = 256, kLine = 100;  // the line at 40 Hz
  gearpulse::ToneMap tones{kBins, 8, 240, 8, 0.4, 0.1};
  std::mt19937_64 rng{9};
  std::exponential_distribution<double> noise{1.0};
  std::vector<double> power = std::vector<double>(kBins), floor = std::vector<double>(kBins, 1.0);

  void run(int hops, double line, double from_hz, double to_hz) {
    const double order[] = {1.0};
    for (int hop = 0; hop < hops; ++hop) {
      for (std::size_t k = 0; k < kBins; ++k)
        power[k] = noise(rng);
      power[kLine] += line;
      const double freq = from_hz + (to_hz - from_hz) * hop / hops;
      tones.learn(power.data(), floor.data(), freq, order, false, false);
    }
  }
};

}  // namespace

// While the track holds the engine, the tone map leaves out every multiple of its fundamental (an ignition
// comb's lines, which at an idle stand still for seconds). A comb's multiple stands under its fundamental;
// a line louder than the fundamental at four times it is another line there (a fan at four times the idle),
// and is learned as a tone. Left out with the comb, it stayed unlearned while the idle was tracked, and at
// the next shift the track fell on it (the default rows' van-6 mix, a fan at 109 Hz over an idle at 27 Hz).
TEST_CASE("tone map: a line louder than the tracked fundamental at one of its multiples is learned") {
  constexpr std::size_t kFundamental = 30, kFourth = 120;  // a tracked idle at 12 Hz
  for (const double fourth : {100.0, 5.0}) {  // a fan over the fundamental (50), a comb's line under it
    INFO("line at four times the fundamental " << fourth << " times the noise");
    const gearpulse::ToneMap tones = tones_learned(kFundamental, {{kFundamental, 50.0}, {kFourth, fourth}});
    if (fourth > 50.0)
      CHECK(tones.mean(kFourth) >= gearpulse::ToneMap::kFitLevel);
    else
      CHECK(tones.mean(kFourth) == Approx(1.0));
  }
}

// With the track at half the engine (a lock on the engine's half order), the engine's own 2nd and 3rd
// harmonics stand at four and six times the estimate, louder than the estimate's weak line but under the
// engine's line at twice it, one of the estimate's orders. Learned as tones they would blank the engine's
// orders wherever it later crosses them: a comb's multiple is judged against the estimate's loudest order.
TEST_CASE("tone map: a track at half the engine does not learn the engine's harmonics as tones") {
  constexpr std::size_t kHalf = 30, kEngine = 60, kSecond = 120, kThird = 180;
  const gearpulse::ToneMap tones =
      tones_learned(kHalf, {{kHalf, 5.0}, {kEngine, 100.0}, {kSecond, 60.0}, {kThird, 30.0}});
  CHECK(tones.mean(kSecond) == Approx(1.0));
  CHECK(tones.mean(kThird) == Approx(1.0));
}

// A fixed tone of other equipment stays put while the engine moves; an engine's line off the track's orders
// (a half order, the alternator's whine, an order of an engine the track does not hold) stands in a bin only
// while the engine holds its speed, and at 30-40 dB over the noise it raised the bin's mean past the fit
// level within 2-3 s: the bins marked as tones grew to a third of the band and blanked the engine's own
// orders after the next shift. A bin is marked only once the estimate has moved by about three resolution
// bins (2.88: the half order's line leaves a peak's 3 dB width by then) while the bin stood as a line's
// peak above the fit level.
TEST_CASE("tone map: a line is marked a tone once it has stayed put while the estimate moved") {
  LineFeed feed;
  const auto run = [&](int hops, double line, double from_hz, double to_hz) {
    feed.run(hops, line, from_hz, to_hz);
    feed.tones.mark(NAN);  // no prediction: no bin is near the engine's lines
  };
  run(300, 0.0, 20.0, 20.0);      // 30 s of noise
  run(100, 10000.0, 20.0, 20.0);  // a line 40 dB over the noise for 10 s, the estimate held
  CHECK(feed.tones.mean(LineFeed::kLine) >= gearpulse::ToneMap::kFitLevel);
  CHECK_FALSE(feed.tones.near(LineFeed::kLine));
  run(30, 10000.0, 20.0, 35.0);  // the line stays while the estimate moves 15 Hz: a tone
  CHECK(feed.tones.near(LineFeed::kLine));
}

// A bin's mean counts as background (what its readings are divided by) past the fit level, where the engine's
// lines may stand (within a resolution bin of a multiple of half the track's prediction), only if the bin is
// a learned tone: a loud engine's own line held in a bin (a cruise, a steady 2nd harmonic) raised the mean
// far past the fit level, and its later readings, divided by that mean, read as noise, so that the engine's
// own orders scored as absent while a state at twice or three times the engine read the comb's upper lines.
// Away from the engine's lines (a fan the engine never moves far enough from to mark) the mean counts as
// before.
TEST_CASE("tone map: a line held under a still estimate is not divided out as a tone") {
  LineFeed feed;
  const gearpulse::ToneMap& tones = feed.tones;
  constexpr std::size_t kLine = LineFeed::kLine;  // at 40 Hz
  feed.run(300, 0.0, 20.0, 20.0);                 // 30 s of noise
  feed.run(100, 10000.0, 20.0, 20.0);             // a line 40 dB over the noise for 10 s, the estimate held
  REQUIRE(tones.mean(kLine) > 10.0 * gearpulse::ToneMap::kFitLevel);
  CHECK_FALSE(tones.learned(kLine));
  feed.tones.mark(20.0);  // the line at twice the prediction: the engine's 2nd harmonic
  CHECK(tones.background(kLine) == Approx(gearpulse::ToneMap::kFitLevel - 1.0));
  feed.tones.mark(23.0);  // no multiple of half the prediction within a resolution bin
  CHECK(tones.background(kLine) == Approx(tones.mean(kLine) - 1.0));
  feed.run(30, 10000.0, 20.0, 35.0);  // the line stays while the estimate moves 15 Hz: a tone
  feed.tones.mark(20.0);
  CHECK(tones.learned(kLine));
  CHECK(tones.background(kLine) == Approx(tones.mean(kLine) - 1.0));
}
