// The tracker thread's wake-ups: it waits for its work (a block of audio pushed, a GPS report, a step on
// GPS alone) instead of polling, and stop() wakes it.
#include <chrono>
#include <cstdint>
#include <thread>

#include <catch2/catch.hpp>

#include "tests/daemon/live_chain.hpp"
#include "tests/test_util.hpp"

using namespace std::chrono_literals;
using namespace gearpulse::test;
using gearpulse::SpeedSource;

// The tracker thread waits for its work (a block of audio pushed, a GPS report, a step on GPS alone)
// instead of polling the ring every 10 ms: 8 kHz in periods of 512 (15.6 a second) and two reports a
// second wake it about 18 times a second (a poll woke it about 100 times).
TEST_CASE("pipeline: the tracker thread wakes for each period of audio and each GPS report, not to poll") {
  LiveChain chain(512, 60, 0.5);  // about 30 s of GPS
  chain.model.set(one_gear());
  gearpulse::daemon::Pipeline& pipeline = chain.start();
  REQUIRE(wait_for(
      [&] {
        const auto s = pipeline.snapshot();
        return s.source == SpeedSource::kGps && near(s.tracker_freq, kTone, kWander + 0.5);
      },
      20s));
  const auto before = pipeline.snapshot();
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(3s);
  const auto after = pipeline.snapshot();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double per_second = static_cast<double>(after.tracker_turns - before.tracker_turns) / seconds;
  INFO("tracker turns per second " << per_second);
  CHECK(per_second < 40.0);
  // Still on every block: the engine is tracked and the speed is GPS's.
  CHECK(near(after.tracker_freq, kTone, kWander + 0.5));
  CHECK(after.source == SpeedSource::kGps);
}

// How long stop() may take. Once the tracker thread is woken, stop() returns after one look of its own at
// the thread (Pipeline::stop looks every 20 ms) and the threads' exits: 1-50 ms measured in the release
// build, 21-28 ms under ThreadSanitizer beside two live chains, on two cores loaded by other builds. Had
// stop() not woken it, the thread would wait out its wait, up to its 0.25 s heartbeat more. 150 ms lies
// between: the look and 130 ms of room for the exits on a loaded machine. A sanitizer stretches the exits
// (its own work), not the look (a sleep): the room grows by kSanitizerSlowdown, to 2 s, where the bound no
// longer tells a missed wake-up from slow exits but still a stop() that waits for something of seconds
// (its 3 s patience with the capture, the gpsd client's backoff); the release build checks the wake-up.
constexpr double kStopLookMs = 20.0;
constexpr double kStopBoundMs = kStopLookMs + 130.0 * kSanitizerSlowdown;

// Without audio or GPS it wakes for its steps on GPS alone (one every 0.28 s at the default hop and
// window), its heartbeat and the capture's opens; stop() wakes it at once rather than after its wait.
TEST_CASE("pipeline: without audio or GPS the tracker thread wakes a few times a second and stops at once") {
  for (int round = 0; round < 3; ++round) {
    GpsOnly chain;
    gearpulse::daemon::Pipeline& pipeline = chain.start();
    std::this_thread::sleep_for(200ms);
    const auto before = pipeline.snapshot();
    std::this_thread::sleep_for(1s);
    const auto after = pipeline.snapshot();
    const std::uint64_t turns = after.tracker_turns - before.tracker_turns;
    INFO("round " << round << ": " << turns << " tracker turns in 1 s");
    CHECK(turns < 20);
    CHECK(after.stalled.empty());
    const auto t0 = std::chrono::steady_clock::now();
    pipeline.stop();
    const double took_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    INFO("stop() took " << took_ms << " ms");
    CHECK(took_ms < kStopBoundMs);
  }
}
