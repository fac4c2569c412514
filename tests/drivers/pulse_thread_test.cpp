#include <catch2/catch.hpp>

#include <time.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

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

// SCHED_FIFO that is asked for and not granted is shown, so that the daemon can say so. A priority out of
// SCHED_FIFO's range (1..99) is refused even to root; nothing asked, nothing refused.
TEST_CASE("pulse: a real-time set-up asked for and refused is shown in the status") {
  for (const bool asked : {true, false}) {
    INFO("realtime asked: " << asked);
    gearpulse::NullPulseOutput out;
    gearpulse::PulseThreadConfig cfg = pulse_a_metre();
    cfg.realtime = asked;
    cfg.rt_priority = 100;
    gearpulse::PulseThread thread(out, cfg);
    thread.start();
    REQUIRE(within_5s([&] { return thread.status().running; }));
    CHECK(thread.status().realtime_refused == asked);
    CHECK_FALSE(thread.status().realtime_ok);
    thread.stop();
  }
}

// At standstill no edge is due, yet the thread turns its loop once a heartbeat period to show the
// watchdog it is alive.
TEST_CASE("pulse: at standstill the thread beats once a heartbeat period") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThread thread(out, pulse_a_metre());
  thread.start();
  // The heartbeat start() set moves on, beat after beat (each a period, 250 ms, apart). The age is read
  // right after a beat was seen, so 1 s (four periods) is room for the scheduling of a loaded machine,
  // not for a loop that stopped turning.
  std::int64_t beat_ns = 0;
  for (int beat = 0; beat < 3; ++beat) {
    const std::int64_t h0 = thread.status().heartbeat_ns;
    REQUIRE(within_5s([&] { return thread.status().heartbeat_ns > h0; }));
    beat_ns = thread.status().heartbeat_ns;
  }
  CHECK(gearpulse::monotonic_ns() - beat_ns < 1'000'000'000);
  thread.stop();
}

// The daemon starts the train at standstill and sets a speed later: the thread must wake for it, not
// when it next happens to wake. With a 30 s heartbeat period, a thread that only looked at the speed
// when its heartbeat woke it would take the speed up 30 s later.
TEST_CASE("pulse: a start from standstill is taken up at once, not at the next heartbeat") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThreadConfig cfg = pulse_a_metre();
  cfg.heartbeat_period = 30s;
  std::vector<gearpulse::RiseRecord> log(16);
  gearpulse::PulseThread thread(out, cfg, log);
  thread.start();
  // Once the loop has turned it has loaded the standstill and sleeps toward its next heartbeat; the
  // pause only makes sure it is asleep, no assertion depends on its length.
  REQUIRE(within_5s([&] { return thread.status().turns >= 1; }));
  std::this_thread::sleep_for(50ms);
  const std::int64_t set_ns = gearpulse::monotonic_ns();
  thread.set_speed(1000.0);  // 1 kHz: the first rise is due a millisecond after the speed is taken up
  const bool pulsing = within_5s([&] { return thread.logged() > 0; });
  thread.stop();  // wakes the thread: no 30 s join
  REQUIRE(pulsing);
  // The first rise is written a millisecond (a period) and a wake-up after set_speed. 2 s leaves a
  // sanitized build on a loaded machine ample room and is still fifteen times short of the heartbeat.
  const std::int64_t waited = log[0].written_ns - set_ns;
  INFO("first rise " << waited / 1000 << " us after set_speed");
  CHECK(waited < 2'000'000'000);
}

// The thread wakes for its edges, not to look at the speed: at a constant 10 Hz (20 edges a second)
// it turns its loop about once an edge, where a thread polling the speed every 5 ms turned 200 times
// a second.
TEST_CASE("pulse: at a constant speed the thread wakes once an edge, not to poll the speed") {
  gearpulse::NullPulseOutput out;
  gearpulse::PulseThread thread(out, pulse_a_metre());
  thread.start();
  thread.set_speed(10.0);  // 10 Hz
  REQUIRE(within_5s([&] { return thread.pulses() >= 2; }));
  // The edges are counted from the thread's own (atomic) pulse count: the output's counters are the
  // thread's alone while it runs. A rise and a fall a pulse; the fall after the last rise may be due yet.
  const gearpulse::PulseThreadStatus s0 = thread.status();
  // Five periods, 0.5 s: waited for, as a loaded machine may take longer.
  REQUIRE(within_5s([&] { return thread.pulses() >= s0.pulses + 5; }));
  const gearpulse::PulseThreadStatus s1 = thread.status();
  thread.stop();
  const std::uint64_t turns = s1.turns - s0.turns;
  const std::uint64_t edges = 2 * (s1.pulses - s0.pulses);
  INFO(turns << " turns for about " << edges << " edges");
  CHECK(edges >= 10);
  // A turn per edge, and a few to spare (the fall after the last rise, a wake-up of the status reads'
  // timing, a signal's EINTR): a 5 ms poll would add a hundred.
  CHECK(turns <= edges + 5);
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
  // Wait for pulses rather than a fixed time: a sanitized build on a loaded machine may stretch the
  // wake-up for the new speed past any short sleep.
  CHECK(within_5s([&] { return thread.pulses() >= 3; }));
  thread.stop();
  // The first device is still the one driven, and alive: it carries the pulses after the refused attach.
  CHECK(driven->rises() > 0);
  CHECK(driven->rises() == driven->falls());
}

TEST_CASE("pulse: a late output reports its device's failed writes and their errno") {
  // A device whose every write fails with EIO (a GPIO chip whose device went away).
  class FailingOutput final : public gearpulse::PulseOutput {
   public:
    void rise() noexcept override { ++errors_; }
    void fall() noexcept override {}
    [[nodiscard]] std::uint64_t errors() const noexcept override { return errors_; }
    [[nodiscard]] int last_error() const noexcept override { return errors_ > 0 ? EIO : 0; }
    [[nodiscard]] std::string describe() const override { return "failing"; }

   private:
    std::uint64_t errors_ = 0;
  };
  gearpulse::LateOutput late;
  CHECK(late.last_error() == 0);  // nothing attached: nothing failed
  REQUIRE(late.attach(std::make_unique<FailingOutput>()));
  CHECK(late.last_error() == 0);
  late.rise();
  late.rise();
  CHECK(late.errors() == 2);
  CHECK(late.last_error() == EIO);
}

namespace {

// An output each of whose writes takes `write_ns` while `slow` (a USB adapter's round trip).
struct SlowOutput final : gearpulse::PulseOutput {
  std::atomic<bool> slow{true};
  std::int64_t write_ns = 1'000'000;
  void wait() const noexcept {
    if (!slow.load()) return;
    const timespec ts{0, static_cast<long>(write_ns)};
    ::nanosleep(&ts, nullptr);
  }
  void rise() noexcept override { wait(); }
  void fall() noexcept override { wait(); }
  [[nodiscard]] std::uint64_t errors() const noexcept override { return 0; }
  [[nodiscard]] std::string describe() const override { return "slow"; }
};

}  // namespace

TEST_CASE("pulse: an output slower than its edges keeps the thread beating, and a stop ends it") {
  // 700 Hz (edges 0.7 ms apart) on writes of 1 ms each: a pass that wrote every edge due by the end of its
  // last write never ended, so the heartbeat aged past the watchdog's limit and stop() never returned.
  SlowOutput out;
  gearpulse::PulseThreadConfig cfg;
  cfg.pulse.pulses_per_km = 1000.0;
  cfg.pulse.max_freq_hz = 1000.0;
  cfg.pulse.pulse_width_s = 0.0005;
  gearpulse::PulseThread thread(out, cfg);
  thread.start();
  thread.set_speed(700.0);
  std::int64_t worst_age = 0;
  for (int i = 0; i < 30; ++i) {
    std::this_thread::sleep_for(100ms);
    worst_age = std::max(worst_age, gearpulse::monotonic_ns() - thread.status().heartbeat_ns);
  }
  CHECK(worst_age < 1'000'000'000);
  const gearpulse::PulseThreadStatus st = thread.status();
  CHECK(st.discarded > 0);  // the pulses it could not write, dropped beyond half a second's
  out.slow = false;         // lets the old loop end too, so the test fails rather than hangs
  thread.set_speed(0.0);
  const auto asked = std::chrono::steady_clock::now();
  thread.stop();
  CHECK(std::chrono::steady_clock::now() - asked < 2s);
}
