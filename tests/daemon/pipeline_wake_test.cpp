// The tracker thread's wake-ups: it waits for its work (a block of audio pushed, a GPS report, a step on
// GPS alone) instead of polling, and stop() wakes it.
#include <chrono>
#include <cstdint>
#include <thread>

#include <catch2/catch.hpp>

#include "tests/daemon/live_chain.hpp"

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
    CHECK(took_ms < 150.0);
  }
}
