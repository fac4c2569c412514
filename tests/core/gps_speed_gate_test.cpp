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
