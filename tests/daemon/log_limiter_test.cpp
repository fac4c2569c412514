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
