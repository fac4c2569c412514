// GPS glitches kept from the pulse train and the training store: the gate on its own.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>

#include "core/gps_speed_gate.hpp"

using gearpulse::GpsSpeedGate;
using Verdict = GpsSpeedGate::Verdict;

namespace {
const double kNoFixTime = std::nan("");
}  // namespace

TEST_CASE("gps gate: a drive's speeds pass, hard braking and launches included") {
  GpsSpeedGate gate;
  double v = 0.0;
  for (int i = 0; i < 100; ++i) {  // 0 -> 30 m/s at 3 m/s^2, 10 Hz, then braking at 9 m/s^2
    v = std::min(30.0, v + 0.3);
    CHECK(gate.check(kNoFixTime, i * 0.1, v) == Verdict::kAccepted);
  }
  for (int i = 100; i < 134; ++i) {
    v = std::max(0.0, v - 0.9);
    CHECK(gate.check(kNoFixTime, i * 0.1, v) == Verdict::kAccepted);
  }
}

TEST_CASE("gps gate: a spike is refused, and the speed after it is judged against the last good one") {
  GpsSpeedGate gate;
  CHECK(gate.check(kNoFixTime, 0.0, 10.0) == Verdict::kAccepted);
  CHECK(gate.check(kNoFixTime, 1.0, 300.0) == Verdict::kTooFast);   // beyond any car
  CHECK(gate.check(kNoFixTime, 2.0, 80.0) == Verdict::kTooSudden);  // 70 m/s in 2 s
  CHECK(gate.check(kNoFixTime, 2.1, 85.0) == Verdict::kTooSudden);
  CHECK(gate.check(kNoFixTime, 3.0, 11.0) ==
        Verdict::kAccepted);  // back: 1 m/s in 3 s from the last good one
  CHECK(gate.check(kNoFixTime, 3.1, 11.5) == Verdict::kAccepted);  // epoch noise
}

TEST_CASE("gps gate: after a long outage any car speed is taken as it comes") {
  GpsSpeedGate gate;
  CHECK(gate.check(kNoFixTime, 0.0, 0.0) == Verdict::kAccepted);
  CHECK(gate.check(kNoFixTime, 60.0, 33.0) ==
        Verdict::kAccepted);  // a tunnel entered standing, left at 120 km/h
  CHECK(gate.check(kNoFixTime, 60.1, 90.5) == Verdict::kTooFast);
  gate.reset();
  CHECK(gate.check(kNoFixTime, 60.2, 50.0) == Verdict::kAccepted);  // a new connection: no reference
}

TEST_CASE("gps gate: fixes delivered in a burst are judged by their own times") {
  GpsSpeedGate gate;
  CHECK(gate.check(1000.0, 0.0, 10.0) == Verdict::kAccepted);
  // Three seconds of a hard launch delivered within 0.3 s (a reconnect, a slow host).
  CHECK(gate.check(1003.0, 0.3, 35.0) == Verdict::kAccepted);
  CHECK(gate.check(1003.1, 0.35, 90.0) == Verdict::kTooSudden);
}

TEST_CASE("gps gate: untimed fixes are judged by the time since the last accepted one was received") {
  // The receive time of each accepted fix is the reference: a spike 0.1 s after one received at 100.1 s
  // is sudden, whatever the time since the gate was made.
  GpsSpeedGate gate;
  CHECK(gate.check(kNoFixTime, 100.0, 10.0) == Verdict::kAccepted);
  CHECK(gate.check(kNoFixTime, 100.1, 10.5) == Verdict::kAccepted);
  CHECK(gate.check(kNoFixTime, 100.2, 80.0) == Verdict::kTooSudden);
}

TEST_CASE("gps gate: a fix timed before the last one is judged by the receive times") {
  // A receiver's clock stepped back (or fixes delivered out of order): a negative time between fixes
  // would allow no change at all, so a steady speed would be refused; the receive times judge instead,
  // so a steady speed passes and a spike behind the step is still refused.
  GpsSpeedGate gate;
  CHECK(gate.check(1000.0, 0.0, 10.0) == Verdict::kAccepted);
  CHECK(gate.check(999.0, 0.1, 10.0) == Verdict::kAccepted);
  CHECK(gate.check(998.0, 0.2, 85.0) == Verdict::kTooSudden);
  CHECK(gate.check(998.5, 1.2, 12.0) == Verdict::kAccepted);
}

TEST_CASE("gps gate: two fixes of the same time allow only the noise between them") {
  GpsSpeedGate gate;
  CHECK(gate.check(1000.0, 0.0, 10.0) == Verdict::kAccepted);
  CHECK(gate.check(1000.0, 0.1, 60.0) == Verdict::kTooSudden);
}

TEST_CASE("gps gate: the receiver's noise is allowed on top of the acceleration") {
  // 1 m/s in 0.05 s is 20 m/s^2 taken alone, but within the 1 m/s a receiver jitters from epoch to epoch.
  GpsSpeedGate gate;
  CHECK(gate.check(kNoFixTime, 0.0, 10.0) == Verdict::kAccepted);
  CHECK(gate.check(kNoFixTime, 0.05, 11.0) == Verdict::kAccepted);
}

TEST_CASE("gps gate: a timed fix after an untimed one is judged by the receive times") {
  // The last accepted fix had no time of its own: the time between the two is the receive times', and a
  // spike 0.1 s later is refused, not let through for want of a fix time to compare with.
  GpsSpeedGate gate;
  CHECK(gate.check(kNoFixTime, 10.0, 10.0) == Verdict::kAccepted);
  CHECK(gate.check(1000.0, 10.1, 80.0) == Verdict::kTooSudden);
}

TEST_CASE("gps gate: the reference age and the allowed change are inclusive") {
  // A speed exactly reference_s old is still a reference: 70 m/s in 5 s is beyond 12 m/s^2 plus noise.
  GpsSpeedGate gate;
  CHECK(gate.check(kNoFixTime, 0.0, 0.0) == Verdict::kAccepted);
  CHECK(gate.check(kNoFixTime, 5.0, 70.0) == Verdict::kTooSudden);
  // A change of exactly max_accel * dt + noise (13 m/s in 1 s) is allowed.
  GpsSpeedGate exact;
  CHECK(exact.check(kNoFixTime, 0.0, 10.0) == Verdict::kAccepted);
  CHECK(exact.check(kNoFixTime, 1.0, 23.0) == Verdict::kAccepted);
}
