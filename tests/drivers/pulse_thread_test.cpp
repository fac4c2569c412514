#include <catch2/catch.hpp>

#include <chrono>
#include <thread>

#include "drivers/pulse_output.hpp"
#include "drivers/pulse_thread.hpp"

using namespace std::chrono_literals;

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
    std::this_thread::sleep_for(std::chrono::milliseconds(30 + 7 * i));
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
