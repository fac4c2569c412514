// The synthesis's output within bounds: bad input, outages never outrun, no revs nor GPS coasts to rest.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>

#include "core/speed_synth.hpp"
#include "tests/core/synth_drives.hpp"

using gearpulse::GearModel;
using gearpulse::kMissing;
using gearpulse::SpeedSource;
using gearpulse::SpeedSynthesizer;
using gearpulse::SynthOutput;

using gearpulse::test::kHatch;
using gearpulse::test::kIdle;
using gearpulse::test::model_of;

TEST_CASE("synth: bad input never produces a bad output") {
  SpeedSynthesizer synth(model_of(kHatch));
  const double nan = kMissing, inf = std::numeric_limits<double>::infinity();
  const double inputs[][3] = {{0, 10, 30},   {1, nan, nan},  {nan, 5, 5}, {0.5, -3, 30},      {2, inf, -5},
                              {2, nan, inf}, {1e9, nan, 40}, {1e9, 0, 0}, {1e9 + 1, nan, 1e6}};
  for (const auto& in : inputs) {
    const SynthOutput o = synth.step(in[0], in[1], in[2]);
    CHECK(std::isfinite(o.speed));
    CHECK(o.speed >= 0.0);
    CHECK(o.gear >= 0);
    CHECK(o.gear <= 5);
  }
}

TEST_CASE("synth: whatever the input, an outage never outruns what GPS or the engine last showed") {
  // Random segments of GPS present or lost, and of a frequency that fits a gear, idles, jumps about
  // anywhere in the band or is lost, at 1 and 10 steps per second. Through an outage the output can
  // come only from the last GPS speed (coasting never gains) or from a gear's theta x a frequency seen
  // since: it must never exceed the larger of the two by more than a car gains in a few seconds.
  const double rate = GENERATE(1.0, 10.0);
  INFO("steps per second " << rate);
  const auto model = model_of(kHatch);
  const double theta_top = kHatch.back();
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int violations = 0;
  double worst = 0.0;
  for (int drive = 0; drive < 40; ++drive) {
    SpeedSynthesizer synth(model);
    double t = 0.0, v = 0.0, last_gps = 0.0, top_freq = 0.0;
    for (int segment = 0; segment < 20; ++segment) {
      const bool gps = u(rng) < 0.5;
      const int kind = static_cast<int>(u(rng) * 4.0);  // 0 in gear, 1 idle, 2 anywhere, 3 lost
      const int gear = static_cast<int>(u(rng) * static_cast<double>(kHatch.size()));
      const double accel = (u(rng) - 0.5) * 3.0;
      const int steps = static_cast<int>((1.0 + u(rng) * 19.0) * rate);
      for (int k = 0; k < steps; ++k) {
        t += 1.0 / rate;
        v = std::clamp(v + accel / rate, 0.0, 40.0);
        double freq = kMissing;
        if (kind == 0) freq = v / kHatch[static_cast<std::size_t>(gear)];
        if (kind == 1) freq = kIdle * (0.95 + 0.1 * u(rng));
        if (kind == 2) freq = 10.0 + 90.0 * u(rng);
        const SynthOutput o = synth.step(t, gps ? v : kMissing, freq);
        REQUIRE(std::isfinite(o.speed));
        REQUIRE(o.speed >= 0.0);
        if (gps) {
          last_gps = v;
          top_freq = 0.0;
          continue;
        }
        if (std::isfinite(freq)) top_freq = std::max(top_freq, freq);
        const double bound = std::max(last_gps, theta_top * top_freq) + 3.0;
        if (o.speed > bound) {
          ++violations;
          worst = std::max(worst, o.speed - bound);
        }
      }
    }
  }
  INFO("outage outputs beyond the bound: " << violations << ", worst by " << worst << " m/s");
  CHECK(violations == 0);
}

// A tracker that never locks (no ripple on this car's supply) while GPS shows a steady cruise, then GPS lost
// too: nothing says the car keeps its speed. The declutched mode held the belief under GPS (every gear
// fades without revs) and learned the cruise as its deceleration, zero, so the output stayed at the last
// GPS speed for good: 390 s at 72 km/h, 7.8 km of pulses for a car that may have stopped.
TEST_CASE("synth: with neither GPS nor engine frequency the speed is not held for good") {
  SpeedSynthesizer synth(model_of(kHatch));
  for (int k = 0; k <= 10; ++k)
    synth.step(k, 20.0, kMissing);
  double last = 20.0;
  for (int k = 11; k <= 400; ++k) {
    const SynthOutput o = synth.step(k, kMissing, kMissing);
    REQUIRE(o.speed <= last + 1e-9);  // never gaining speed
    last = o.speed;
  }
  CHECK(last == 0.0);
}

// The same with the engine seen under GPS, declutched a few seconds at a steady speed before the cruise
// went on in fifth: those fixes taught the clutch a deceleration of zero, which alone made the car roll on
// at 72 km/h for good once the revs and GPS were both lost.
TEST_CASE("synth: a few steady fixes declutched do not make the car roll on for good") {
  SpeedSynthesizer synth(model_of(kHatch));
  const double v = 20.0, fifth = v / kHatch[4];
  int k = 0;
  for (; k < 30; ++k)
    synth.step(k, v, fifth);
  for (; k < 34; ++k)
    synth.step(k, v, kIdle);
  for (; k < 90; ++k)
    synth.step(k, v, fifth);
  double last = v;
  for (; k < 400; ++k) {
    const SynthOutput o = synth.step(k, kMissing, kMissing);
    REQUIRE(o.speed <= last + 1e-9);
    last = o.speed;
  }
  CHECK(last == 0.0);
}

TEST_CASE("synth: a cold start without GPS reports no speed until it knows, then a car at rest") {
  // The daemon starts in an underground car park: no fix and, for the first moments, no frequency track.
  auto model = std::make_shared<GearModel>(*model_of(kHatch));
  model->extra["idle"] = {{"freq", kIdle}, {"sd", 0.3}, {"samples", 500}};
  SpeedSynthesizer synth(model);
  for (int k = 0; k < 5; ++k) {
    const SynthOutput out = synth.step(0.1 * k, kMissing, kMissing);
    CHECK(out.source == SpeedSource::kNone);
    CHECK(out.speed == 0.0);
    CHECK(out.gear == 0);
  }
  // Then the engine idles: a car at rest, not the most used gear at idle revs.
  for (int k = 5; k < 50; ++k) {
    const SynthOutput out = synth.step(0.1 * k, kMissing, kIdle);
    INFO("t = " << 0.1 * k);
    CHECK(out.speed == 0.0);
    CHECK(out.gear == 0);
  }
}

TEST_CASE("synth: coasting never gains speed, whatever GPS taught while no gear explained the revs") {
  // GPS ramps up at 1 m/s^2 while the engine frequency stays put (a slipping clutch, or a tracker stuck
  // on a fixed tone): no gear explains it, the filter reads declutched and GPS shows it gaining speed.
  SpeedSynthesizer synth(model_of(kHatch));
  double top = 0.0;
  for (int k = 0; k < 20; ++k)
    synth.step(k, 5.0 + k, 50.0);
  const double last_gps = 24.0;
  for (int k = 20; k < 90; ++k) {
    const SynthOutput out = synth.step(k, kMissing, 50.0);
    top = std::max(top, out.speed);
  }
  INFO("highest outage speed " << top << " m/s after GPS's last " << last_gps);
  CHECK(top <= last_gps + 3.0);
}

TEST_CASE("synth: with the frequency lost from the start the speed coasts down, it never takes off") {
  // The tracker never locks (no ripple, a card unplugged): GPS alone from a cold start at rest, then
  // GPS goes too. Moving off is how a car leaves standstill, not a state it drives in: with nothing to
  // tell the engine's revs, its launch acceleration must not carry the speed away.
  const double rate = GENERATE(1.0, 10.0);
  INFO("steps per second " << rate);
  SpeedSynthesizer synth(model_of(kHatch));
  const double gps = 16.0;
  for (int k = 0; k < static_cast<int>(10 * rate); ++k)
    synth.step(k / rate, k < static_cast<int>(2 * rate) ? kMissing : gps, kMissing);
  double top = 0.0;
  for (int k = static_cast<int>(10 * rate); k < static_cast<int>(40 * rate); ++k) {
    const SynthOutput out = synth.step(k / rate, kMissing, kMissing);
    top = std::max(top, out.speed);
    CHECK(out.source == gearpulse::SpeedSource::kCoast);
  }
  INFO("highest outage speed " << top << " m/s after GPS's " << gps);
  CHECK(top <= gps + 0.5);
}
