#include <catch2/catch.hpp>

#include <chrono>
#include <memory>
#include <thread>

#include "drivers/clock.hpp"
#include "drivers/late_output.hpp"
#include "drivers/pulse_output.hpp"
#include "drivers/pulse_thread.hpp"

using namespace std::chrono_literals;

namespace {

// A pulse a metre: the speed in m/s is the pulse rate in Hz.
gearpulse::PulseThreadConfig pulse_a_metre() {
  gearpulse::PulseThreadConfig cfg;
  cfg.pulse.pulses_per_km = 1000.0;
  return cfg;
}

// Waits for `done` to hold, polling every millisecond, and returns whether it did. The 5 s only bound a
// failing test (what takes milliseconds here may take a sanitized build on a loaded machine far longer);
// no assertion depends on how soon `done` holds.
template <class Done>
bool within_5s(Done done) {
  const auto end = std::chrono::steady_clock::now() + 5s;
  while (!done() && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(1ms);
  return done();
}

}  // namespace

TEST_CASE("pulse: the thread leaves the output low whenever it is stopped") {
  for (int i = 0; i < 5; ++i) {
    gearpulse::NullPulseOutput out;
    gearpulse::PulseThreadConfig cfg;
    cfg.pulse.pulses_per_km = 1000.0;
    cfg.pulse.pulse_width_s = 0.004;  // high 40 % of a 100 Hz period: stops often land mid-pulse
    cfg.pulse.max_freq_hz = 200.0;
    gearpulse::PulseThread thread(out, cfg);
    thread.start();
    thread.set_speed(100.0);
    // The first pulse, then a varied time so the stop lands at different phases of the pulse.
    CHECK(within_5s([&] { return thread.pulses() > 0; }));
    std::this_thread::sleep_for(std::chrono::milliseconds(3 + 7 * i));
    thread.stop();
    CHECK(out.rises() == thread.pulses());
    CHECK(out.falls() == out.rises());
    CHECK(out.rises() > 0);
  }
}

TEST_CASE("pulse: the thread refuses a bad configuration before starting") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThreadConfig cfg;
  cfg.pulse.pulses_per_km = -1.0;
  gearpulse::PulseThread thread(out, cfg);
  CHECK_THROWS_WITH(thread.start(), Catch::Contains("pulses_per_km"));
  CHECK_FALSE(thread.status().running);
}

// The daemon starts the train at standstill and sets a speed later: it must be taken up within
// speed_poll, not when the thread next happens to wake.
TEST_CASE(
    "pulse: a start from standstill is taken up within the speed poll, and the thread beats meanwhile") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThreadConfig cfg = pulse_a_metre();
  cfg.speed_poll = 5ms;
  gearpulse::PulseThread thread(out, cfg);
  thread.start();
  // At standstill it still turns its loop: the heartbeat start() set moves on, beat after beat. The age is
  // read right after a beat was seen, so 500 ms (a hundred polls) is room for the scheduling of a loaded
  // machine, not for a loop that stopped turning.
  for (int beat = 0; beat < 3; ++beat) {
    const std::int64_t h0 = thread.status().heartbeat_ns;
    REQUIRE(within_5s([&] { return thread.status().heartbeat_ns > h0; }));
  }
  CHECK(gearpulse::monotonic_ns() - thread.status().heartbeat_ns < 500'000'000);
  const auto set_at = std::chrono::steady_clock::now();
  thread.set_speed(100.0);  // 100 Hz
  const bool pulsing = within_5s([&] { return thread.pulses() > 0; });
  const auto waited = std::chrono::steady_clock::now() - set_at;
  thread.stop();
  CHECK(pulsing);
  // The first pulse is due a poll (5 ms) and a period (10 ms) after the speed is set. At standstill the
  // thread has no edge to wake for (the next one is never): one that did not look at the speed at each
  // poll would not start at all, or only at some longer wake-up. The bound leaves a sanitized build on a
  // loaded machine over thirty times the nominal 15 ms, all of it wake-up latency, which the sanitizers
  // do not stretch; a poll of half a second or more still fails it.
  INFO("first pulse after " << std::chrono::duration_cast<std::chrono::milliseconds>(waited).count()
                            << " ms");
  CHECK(waited < 500ms);
}

// late_edges is how the status says the pulses were not on time: edges a little after their time (the
// wake-up of any sleep) are not late, or every edge would be.
TEST_CASE("pulse: edges on time are not counted late") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThread thread(out, pulse_a_metre());
  thread.start();
  thread.set_speed(50.0);  // 50 Hz
  // Twenty pulses (0.4 s at 50 Hz), waited for rather than slept for: a loaded machine may take longer.
  const bool twenty = within_5s([&] { return thread.pulses() >= 20; });
  thread.stop();
  const auto s = thread.status();
  INFO(s.late_edges << " of " << out.rises() + out.falls() << " edges late, worst " << s.max_late_ns
                    << " ns");
  REQUIRE(twenty);
  // Not every edge: one on time within a millisecond is enough to tell (a loaded machine may make many
  // late).
  CHECK(s.late_edges < out.rises() + out.falls());
}

// A second start() of a running thread is nothing: one train, not a second thread (or an abort).
TEST_CASE("pulse: starting a running thread again keeps the one train") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThread thread(out, pulse_a_metre());
  thread.start();
  thread.set_speed(100.0);
  REQUIRE(within_5s([&] { return thread.pulses() >= 3; }));
  thread.start();
  // The train goes on after the second start: pulses still come, each on the one output.
  const std::uint64_t before = thread.pulses();
  CHECK(within_5s([&] { return thread.pulses() >= before + 3; }));
  thread.stop();
  CHECK(out.rises() == thread.pulses());
  CHECK(out.falls() == out.rises());
  CHECK_FALSE(thread.status().running);
}

TEST_CASE("pulse: a late output takes its device once and refuses a second while driving the first") {
  gearpulse::LateOutput late;
  gearpulse::PulseThread thread(late, pulse_a_metre());
  thread.start();
  auto first = std::make_unique<gearpulse::NullPulseOutput>();
  gearpulse::NullPulseOutput* driven = first.get();
  CHECK_FALSE(late.attached());
  CHECK_FALSE(late.attach(nullptr));
  CHECK(late.attach(std::move(first)));
  CHECK(late.attached());
  thread.set_speed(200.0);  // every pulse on the attached device, so its rises and falls pair
  CHECK_FALSE(late.attach(std::make_unique<gearpulse::NullPulseOutput>()));
  // Wait for pulses rather than a fixed time: the speed is taken up within the speed poll, which a
  // sanitized build on a loaded machine may stretch past any short sleep.
  CHECK(within_5s([&] { return thread.pulses() >= 3; }));
  thread.stop();
  // The first device is still the one driven, and alive: it carries the pulses after the refused attach.
  CHECK(driven->rises() > 0);
  CHECK(driven->rises() == driven->falls());
}
