// The synthesis's step rate: 1 Hz rows and 10 Hz hops alike, a 1 Hz fix held at each hop, a log replayed.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "bench/outage_protocol.hpp"
#include "core/speed_synth.hpp"
#include "tests/core/synth_drives.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::kMissing;
using gearpulse::SpeedSynthesizer;
using gearpulse::SynthOutput;

using gearpulse::test::kHatch;
using gearpulse::test::kKmh;
using gearpulse::test::model_of;
using gearpulse::test::script;

namespace {

// |error| km/h of every outage sample of a simulated drive observed every `period` s (outages of 60 s
// from 120 s in, then every 180 s: the benches' protocol, bench/outage_protocol.hpp). With a fix
// interval, GPS gives a fix only every so many seconds, and every step until the next one is given it
// again, as the daemon gives the newest fresh fix at every tracker hop (flagged new at the first). A fix
// `late` s late gives the true speed of that long before.
std::vector<double> outage_errors(const gearpulse::sim::Drive& drive, double period, std::uint64_t seed,
                                  double fix_interval = 0.0, double late = 0.0) {
  gearpulse::sim::ObservationOptions obs;
  obs.period = period;
  obs.seed = seed;
  SpeedSynthesizer synth(model_of(drive.vehicle.theta));
  std::vector<double> errors;
  double fix = kMissing;
  long fix_index = -1;
  for (const auto& r : gearpulse::sim::observe(drive, obs)) {
    const double t = r.truth.t;
    const bool out = gearpulse::bench::in_outage(t);
    const double measured = late > 0.0 ? gearpulse::sim::truth_at(drive, t - late).speed : r.speed;
    double gps = out ? kMissing : measured;
    bool fresh = true;
    if (fix_interval > 0.0) {
      const long index = std::lround(std::floor(t / fix_interval + 1e-6));
      fresh = !out && index != fix_index;
      if (fresh) {
        fix = measured;
        fix_index = index;
      }
      if (!out) gps = fix;
    }
    const SynthOutput o = synth.step(t, gps, r.freq, fresh);
    if (out) errors.push_back(std::abs(o.speed - r.truth.speed) / kKmh);
  }
  return errors;
}

using gearpulse::bench::quantile;

// Calls f(drive, seed) for each of eight simulated 15-minute drives at 10 Hz (two cars, mixed and urban).
template <class F>
void for_each_test_drive(F f) {
  for (const char* name : {"hatch-5", "close-6"}) {
    for (const auto style : {gearpulse::sim::DrivingStyle::kMixed, gearpulse::sim::DrivingStyle::kUrban}) {
      for (const std::uint64_t seed : {7, 8})
        f(gearpulse::sim::simulate_drive(gearpulse::sim::vehicle_preset(name),
                                         {.style = style, .duration = 900.0, .dt = 0.1, .seed = seed}),
          seed);
    }
  }
}

// Share of the errors over `km_h`.
double share_beyond(const std::vector<double>& e, double km_h) {
  return static_cast<double>(std::count_if(e.begin(), e.end(), [&](double x) { return x > km_h; })) /
         static_cast<double>(e.size());
}

// Over the test drives, the outages observed as `tried` err as little as those observed as `reference`
// (each: drive, seed -> outage errors): the median under 1 km/h, the share beyond 5 km/h and the p95 at most
// a fifth over the reference's.
template <class Reference, class Tried>
void check_as_good(const char* reference_name, Reference reference, const char* tried_name, Tried tried) {
  std::vector<double> ref, got;
  for_each_test_drive([&](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
    const auto a = reference(drive, seed), b = tried(drive, seed);
    ref.insert(ref.end(), a.begin(), a.end());
    got.insert(got.end(), b.begin(), b.end());
  });
  INFO(reference_name << ": median " << quantile(ref, 0.5) << " km/h, p95 " << quantile(ref, 0.95) << ", "
                      << 100.0 * share_beyond(ref, 5.0) << " % beyond 5 km/h; " << tried_name << ": "
                      << quantile(got, 0.5) << ", " << quantile(got, 0.95) << ", "
                      << 100.0 * share_beyond(got, 5.0) << " %");
  CHECK(quantile(got, 0.5) < 1.0);
  CHECK(share_beyond(got, 5.0) < 1.2 * share_beyond(ref, 5.0) + 0.005);
  CHECK(quantile(got, 0.95) < 1.2 * quantile(ref, 0.95) + 0.3);
}

}  // namespace

TEST_CASE("synth: outage speeds do not depend on the step rate") {
  // The same drives, observed at 1 Hz (GPS, logs) and at 10 Hz (the tracker's hops): the filter's motion,
  // mode changes and evidence are per second, so both rates give about the same speeds.
  std::vector<double> slow, fast;
  for_each_test_drive([&](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
    const auto one = outage_errors(drive, 1.0, seed + 4), ten = outage_errors(drive, 0.1, seed + 4);
    slow.insert(slow.end(), one.begin(), one.end());
    fast.insert(fast.end(), ten.begin(), ten.end());
  });
  const auto beyond = share_beyond;
  INFO("1 Hz median " << quantile(slow, 0.5) << " km/h, " << 100.0 * beyond(slow, 10.0)
                      << " % beyond 10 km/h; 10 Hz " << quantile(fast, 0.5) << ", "
                      << 100.0 * beyond(fast, 10.0) << " %");
  CHECK(quantile(slow, 0.5) < 1.0);
  CHECK(quantile(fast, 0.5) < 1.0);
  CHECK(beyond(fast, 10.0) < 2.0 * beyond(slow, 10.0) + 0.03);
}

TEST_CASE("synth: at 10 Hz hops given a 1 Hz fix at each, outages are followed as with a fix at every hop") {
  // The daemon steps the synthesis at every tracker hop and gives it the newest fresh fix each time: one a
  // second from most receivers, so ten steps see the same fix. Measured again at each, a fix held the speed
  // to a value up to a second old, and the deceleration learned declutched came out at a fraction of the
  // car's.
  check_as_good(
      "a fix at every hop",
      [](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
        return outage_errors(drive, 0.1, seed + 4);
      },
      "a 1 Hz fix held",
      [](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
        return outage_errors(drive, 0.1, seed + 4, 1.0);
      });
}

TEST_CASE("synth: a late receiver's ten fixes a second weigh as its one fix a second") {
  // A receiver 0.6 s late, at 1 and at 10 fixes a second, both stepped at the tracker's hops. Its fixes'
  // departures from the model (the lag's error times the acceleration) last about a second: counted as ten
  // independent measurements a second they drove the modes' belief ten times as hard, and outages at 10 Hz
  // erred more than at 1 Hz.
  check_as_good(
      "1 Hz fixes",
      [](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
        return outage_errors(drive, 0.1, seed + 4, 1.0, 0.6);
      },
      "10 Hz fixes",
      [](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
        return outage_errors(drive, 0.1, seed + 4, 0.1, 0.6);
      });
}

// A log written at the tracker's hop holds each 1 Hz fix on the rows until the next, as the daemon holds it:
// `gearpulse replay` measures a held fix once, as the daemon does, and so answers as the daemon's steps do.
TEST_CASE("synth: replaying a log with held fixes steps as the daemon does, each fix measured once") {
  const auto fixes = script(0.0, {{0, 0.0, 5}, {1, 1.5, 4}, {2, 1.0, 6}, {3, 0.4, 8}, {3, -1.2, 6}}, kHatch);
  SpeedSynthesizer live(model_of(kHatch)), logged(model_of(kHatch));
  gearpulse::LogReplayer replayer(logged);
  const double outage_from = 24.0;
  for (std::size_t i = 0; i + 1 < fixes.size(); ++i) {
    for (int k = 0; k < 10; ++k) {
      const double t = fixes[i].t + 0.1 * k;
      const double freq = fixes[i].freq + (fixes[i + 1].freq - fixes[i].freq) * 0.1 * k;
      const double gps = t < outage_from ? fixes[i].speed : kMissing;
      const SynthOutput a = live.step(t, gps, freq, k == 0);
      const SynthOutput b = replayer.step({t, gps, freq});
      INFO("t = " << t);
      REQUIRE(b.speed == a.speed);
      REQUIRE(b.gear == a.gear);
      REQUIRE(b.source == a.source);
    }
  }
}
