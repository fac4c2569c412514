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
    const auto set_at = std::chrono::steady_clock::now();
    while (thread.pulses() == 0 && std::chrono::steady_clock::now() - set_at < 5s)
      std::this_thread::sleep_for(1ms);
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
  std::this_thread::sleep_for(50ms);
  // At standstill it still turns its loop: the watchdog sees a heartbeat younger than a few polls.
  const std::int64_t h0 = thread.status().heartbeat_ns;
  std::this_thread::sleep_for(50ms);
  CHECK(thread.status().heartbeat_ns > h0);
  CHECK(gearpulse::monotonic_ns() - thread.status().heartbeat_ns < 500'000'000);
  const auto set_at = std::chrono::steady_clock::now();
  thread.set_speed(100.0);  // 100 Hz
  while (thread.pulses() == 0 && std::chrono::steady_clock::now() - set_at < 2s)
    std::this_thread::sleep_for(1ms);
  const auto waited = std::chrono::steady_clock::now() - set_at;
  thread.stop();
  CHECK(thread.pulses() > 0);
  CHECK(waited < 200ms);
}

// late_edges is how the status says the pulses were not on time: edges a little after their time (the
// wake-up of any sleep) are not late, or every edge would be.
TEST_CASE("pulse: edges on time are not counted late") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThread thread(out, pulse_a_metre());
  thread.start();
  thread.set_speed(50.0);  // 50 Hz
  std::this_thread::sleep_for(400ms);
  thread.stop();
  const auto s = thread.status();
  INFO(s.late_edges << " of " << out.rises() + out.falls() << " edges late, worst " << s.max_late_ns
                    << " ns");
  REQUIRE(s.pulses >= 10);
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
  std::this_thread::sleep_for(50ms);
  thread.start();
  std::this_thread::sleep_for(50ms);
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
  const auto set_at = std::chrono::steady_clock::now();
  while (thread.pulses() < 3 && std::chrono::steady_clock::now() - set_at < 5s)
    std::this_thread::sleep_for(1ms);
  thread.stop();
  // The first device is still the one driven, and alive: it carries the pulses after the refused attach.
  CHECK(driven->rises() > 0);
  CHECK(driven->rises() == driven->falls());
}
