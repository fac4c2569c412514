// What the daemon says about faults that repeat: a fault across attempts is said once per spell.
#include <catch2/catch.hpp>

#include "daemon/log_limiter.hpp"

using gearpulse::daemon::FaultSpell;
using gearpulse::daemon::LogLimiter;

TEST_CASE("log: a fault that repeats the same way is said once, again when it changes, and its end once") {
  FaultSpell spell;
  CHECK_FALSE(spell.succeeded());  // working from the start: nothing to say
  CHECK(spell.failed("cannot write: No space left on device"));
  CHECK(spell.failing());
  CHECK_FALSE(spell.failed("cannot write: No space left on device"));
  CHECK_FALSE(spell.failed("cannot write: No space left on device"));
  CHECK(spell.what() == "cannot write: No space left on device");
  CHECK(spell.failed("cannot write: Read-only file system"));
  CHECK(spell.succeeded());
  CHECK_FALSE(spell.failing());
  CHECK_FALSE(spell.succeeded());
  CHECK(spell.failed("cannot write: Read-only file system"));  // a new spell is said again
}

TEST_CASE("log: a fault logged is held back for the interval, each kind on its own") {
  LogLimiter limiter(std::chrono::seconds(3600));
  std::uint64_t suppressed = 99;
  CHECK(limiter.allow("gps", suppressed));
  CHECK(suppressed == 0);
  CHECK_FALSE(limiter.allow("gps", suppressed));
  CHECK_FALSE(limiter.allow("gps", suppressed));
  CHECK(limiter.allow("audio", suppressed));  // another key is its own
  limiter.reset("gps");
  CHECK(limiter.allow("gps", suppressed));
}

TEST_CASE("log: a device state that comes and goes is said when it starts and ends, at most once a minute") {
  using gearpulse::daemon::StateFault;
  using Say = StateFault::Say;
  using namespace std::chrono_literals;
  StateFault lost(60s);
  auto t = StateFault::Clock::time_point{} + 1000s;
  std::uint64_t starts = 0;
  CHECK(lost.update(false, t, starts) == Say::kNothing);  // fine from the start: nothing to say
  CHECK(lost.update(true, t, starts) == Say::kStart);
  CHECK(starts == 1);
  CHECK(lost.update(true, t + 1s, starts) == Say::kNothing);  // still lost: said already
  CHECK(lost.update(false, t + 2s, starts) == Say::kEnd);
  // A loose connector: lost and back again and again within the minute; nothing more is said.
  for (int i = 0; i < 20; ++i) {
    CHECK(lost.update(true, t + 3s + i * 1s, starts) == Say::kNothing);
    CHECK(lost.update(false, t + 3s + i * 1s + 500ms, starts) == Say::kNothing);
  }
  // Lost again and for good: said once the minute since the last start said is over, with the count.
  CHECK(lost.update(true, t + 30s, starts) == Say::kNothing);
  CHECK(lost.update(true, t + 59s, starts) == Say::kNothing);
  starts = 0;
  CHECK(lost.update(true, t + 60s, starts) == Say::kStart);
  CHECK(starts == 21);
  CHECK(lost.update(true, t + 200s, starts) == Say::kNothing);
  CHECK(lost.update(false, t + 201s, starts) == Say::kEnd);
  // Long after: a new start is said at once, as the first.
  CHECK(lost.update(true, t + 400s, starts) == Say::kStart);
  CHECK(starts == 1);
}
