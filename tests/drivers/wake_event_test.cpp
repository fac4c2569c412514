// WakeEvent: a signal is kept until a wait or take_signals() takes it, and fd() shows it pending.
#include <catch2/catch.hpp>

#include <poll.h>

#include <chrono>
#include <cstdint>
#include <thread>

#include "drivers/clock.hpp"
#include "drivers/wake_event.hpp"

using namespace std::chrono_literals;
using gearpulse::monotonic_ns;
using gearpulse::WakeEvent;

namespace {

// Whether a signal is pending: fd() polls readable without waiting.
bool pending(const WakeEvent& wake) {
  pollfd pfd{wake.fd(), POLLIN, 0};
  return ::poll(&pfd, 1, 0) == 1 && (pfd.revents & POLLIN);
}

// The waits a signal must cut short: 5 s, of which a wait that returns for a signal takes well under half
// even in a sanitized build on a loaded machine (it is one ppoll and one read).
constexpr std::int64_t kLongWaitNs = 5'000'000'000;

}  // namespace

TEST_CASE("wake event: a signal given while nobody waits makes the next wait return at once") {
  WakeEvent wake;
  CHECK_FALSE(pending(wake));
  wake.signal();
  wake.signal();
  CHECK(pending(wake));
  const std::int64_t t0 = monotonic_ns();
  wake.wait_until(t0 + kLongWaitNs);
  CHECK(monotonic_ns() - t0 < kLongWaitNs / 2);
  // The wait took both signals: nothing is pending, and the next wait lasts to its time.
  CHECK_FALSE(pending(wake));
  const std::int64_t t1 = monotonic_ns();
  wake.wait_until(t1 + 50'000'000);
  CHECK(monotonic_ns() - t1 >= 50'000'000);
}

TEST_CASE("wake event: take_signals takes what is pending without waiting") {
  WakeEvent wake;
  wake.take_signals();  // nothing pending: returns at once all the same
  wake.signal();
  REQUIRE(pending(wake));
  wake.take_signals();
  CHECK_FALSE(pending(wake));
  const std::int64_t t0 = monotonic_ns();
  wake.wait_until(t0 + 50'000'000);
  CHECK(monotonic_ns() - t0 >= 50'000'000);
}

TEST_CASE("wake event: a signal from another thread wakes a waiter") {
  WakeEvent wake;
  std::thread giver([&wake] {
    std::this_thread::sleep_for(20ms);
    wake.signal();
  });
  const std::int64_t t0 = monotonic_ns();
  wake.wait_until(t0 + kLongWaitNs);
  const std::int64_t took = monotonic_ns() - t0;
  giver.join();
  CHECK(took < kLongWaitNs / 2);
}
