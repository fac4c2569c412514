// The journal's lines on the pulse output name it as the status does: the PTY's path or chip:line.
// GPS that comes and goes is said at most once a minute.
#include <catch2/catch.hpp>

#include <chrono>

#include "daemon/change_reporter.hpp"
#include "daemon/config.hpp"
#include "tests/daemon/log_lines.hpp"

using gearpulse::SpeedSource;
using gearpulse::daemon::ChangeReporter;
using gearpulse::daemon::Config;
using gearpulse::daemon::GpsState;
using gearpulse::daemon::OutputKind;
using gearpulse::daemon::OutputState;
using gearpulse::daemon::PipelineSnapshot;

namespace {
// A snapshot whose GPS is in `state`, its last usable fix `age` s old (< 0: none yet).
PipelineSnapshot gps(GpsState state, double age = -1.0) {
  PipelineSnapshot s;
  s.gps_state = state;
  s.gps_age = age;
  return s;
}

// A snapshot whose speed (m/s, in `gear`) comes from `source`: GPS with a fix, the others without one.
PipelineSnapshot speed_from(SpeedSource source, double speed = 0.0, int gear = 0) {
  PipelineSnapshot s = gps(source == SpeedSource::kGps ? GpsState::kFix : GpsState::kNoFix, 3.0);
  s.source = source;
  s.speed = speed;
  s.gear = gear;
  return s;
}
}  // namespace

TEST_CASE("changes: an output whose writes fail is named, a GPIO line as chip:line") {
  gearpulse::test::LogLines log;
  Config config;
  config.output.kind = OutputKind::kGpio;
  config.output.chip = "gpiochip1";
  config.output.line = 5;
  ChangeReporter changes(config);
  PipelineSnapshot before;
  before.output_state = OutputState::kOk;
  PipelineSnapshot now = before;
  now.output_state = OutputState::kWriteErrors;
  now.output_error = "3 write(s) failed, the last: Input/output error";
  changes.log(before, now);
  CHECK(log.count("output: writes to gpiochip1:5 are failing (3 write(s) failed, the last: Input/output "
                  "error)") == 1);

  config.output.kind = OutputKind::kPty;
  config.output.path = "/run/gearpulse/pulse";
  ChangeReporter pty_changes(config);
  pty_changes.log(before, now);
  CHECK(log.count("output: writes to /run/gearpulse/pulse are failing") == 1);
}

TEST_CASE("changes: GPS that flaps between fix and none is said once, not at every flap") {
  gearpulse::test::LogLines log;
  Config config;
  ChangeReporter changes(config);
  const PipelineSnapshot fix = gps(GpsState::kFix), none = gps(GpsState::kNoFix, 2.5),
                         down = gps(GpsState::kDisconnected);
  changes.log(down, fix);  // the first fix
  for (int flap = 0; flap < 10; ++flap) {
    changes.log(fix, none);
    changes.log(none, fix);
  }
  CHECK(log.count("gps: no usable fix from gpsd at 127.0.0.1:2947 for 2.5 s") == 1);
  // The first fix and the end of the spell that was said; the other returns are debug lines.
  CHECK(log.count("gps: fix from gpsd at 127.0.0.1:2947") == 2);
  // After a lost connection the fix is news again, straight back or through a spell without one.
  changes.log(fix, down);
  changes.log(down, fix);
  CHECK(log.count("gps: fix from gpsd at 127.0.0.1:2947") == 3);
  changes.log(fix, none);
  changes.log(none, down);
  changes.log(down, none);
  changes.log(none, fix);
  CHECK(log.count("gps: fix from gpsd at 127.0.0.1:2947") == 4);
}

TEST_CASE("changes: waiting for a receiver's first fix is not yet a fault of its antenna") {
  gearpulse::test::LogLines log;
  Config config;
  ChangeReporter changes(config);
  changes.log(gps(GpsState::kDisconnected), gps(GpsState::kNoFix));  // no report yet
  CHECK(log.count("gps: no usable fix from gpsd at 127.0.0.1:2947 yet (a receiver's first fix can take a "
                  "minute") == 1);
}

TEST_CASE("changes: a speed source that flaps between GPS and the engine is said once, not at every flap") {
  gearpulse::test::LogLines log;
  Config config;
  ChangeReporter changes(config);
  const auto source = [](SpeedSource s) { return speed_from(s, 20.0, 3); };
  const PipelineSnapshot none = source(SpeedSource::kNone), by_gps = source(SpeedSource::kGps),
                         engine = source(SpeedSource::kEngine), coast = source(SpeedSource::kCoast);
  changes.log(none, none);  // the daemon starts without a speed
  changes.log(none, by_gps);
  CHECK(log.count("synthesis: speed source none -> gps at 72.0 km/h (gear 3)") == 1);
  for (int flap = 0; flap < 10; ++flap) {
    changes.log(by_gps, engine);
    changes.log(engine, coast);  // a declutch inside the outage
    changes.log(coast, engine);
    changes.log(engine, by_gps);
  }
  CHECK(log.count("synthesis: speed source gps -> engine") == 1);
  CHECK(log.count("synthesis: speed source engine -> gps") == 1);
  CHECK(log.count("synthesis: speed source engine -> coast") == 0);
  CHECK(log.count("synthesis: speed source coast -> engine") == 0);
  CHECK(log.count("synthesis: speed source") == 3);
}

TEST_CASE("changes: GPS that keeps leaving the speed is said again after a minute, with how often it left") {
  gearpulse::test::LogLines log;
  Config config;
  ChangeReporter changes(config);
  const auto source = [](SpeedSource s) { return speed_from(s); };
  const PipelineSnapshot by_gps = source(SpeedSource::kGps), engine = source(SpeedSource::kEngine);
  const auto t0 = std::chrono::steady_clock::now();
  const auto at = [t0](int s) { return t0 + std::chrono::seconds(s); };
  changes.log(by_gps, by_gps, at(0));
  changes.log(by_gps, engine, at(1));
  changes.log(engine, by_gps, at(2));
  for (int flap = 0; flap < 5; ++flap) {  // held back: within the minute
    changes.log(by_gps, engine, at(3 + 2 * flap));
    changes.log(engine, by_gps, at(4 + 2 * flap));
  }
  CHECK(log.count("synthesis: speed source gps -> engine") == 1);
  changes.log(by_gps, engine, at(70));
  CHECK(
      log.count("synthesis: speed source gps -> engine at 0.0 km/h (gear 0) (GPS left 6 times since the last "
                "line said so)") == 1);
  changes.log(engine, by_gps, at(71));
  CHECK(log.count("synthesis: speed source engine -> gps") == 2);
  // Away again twice within the minute, and still away when it is over: said then, with no change.
  changes.log(by_gps, engine, at(72));
  changes.log(engine, by_gps, at(73));
  changes.log(by_gps, engine, at(74));
  changes.log(engine, engine, at(100));
  CHECK(log.count("synthesis: speed source engine at") == 0);
  changes.log(engine, engine, at(140));
  CHECK(log.count("synthesis: speed source engine at 0.0 km/h (gear 0) (GPS left 2 times since the last line "
                  "said so)") == 1);
}

TEST_CASE("changes: pulses dropped because the line cannot keep up are said, at most once a minute") {
  gearpulse::test::LogLines log;
  Config config;
  config.output.kind = OutputKind::kPty;
  config.output.path = "/run/gearpulse/pulse";
  ChangeReporter changes(config);
  PipelineSnapshot before, now;
  now.pulses_discarded = 12;
  changes.log(before, now);
  CHECK(
      log.count("output: pulses come due faster than /run/gearpulse/pulse takes them: 12 owed beyond half a "
                "second at output.max_frequency dropped (total 12)") == 1);
  PipelineSnapshot later = now;
  later.pulses_discarded = 20;
  changes.log(now, later);
  CHECK(log.count("output: pulses come due faster than") == 1);
}

// audio.realtime that is not granted left its threads at the normal priority with nothing said, while the
// overrun lines advised to set it.
TEST_CASE("changes: a thread refused the real-time set-up is said once, with its priority") {
  gearpulse::test::LogLines log;
  Config config;
  config.audio.realtime = true;
  config.audio.rt_priority = 88;
  ChangeReporter changes(config);
  const PipelineSnapshot before;
  PipelineSnapshot now;
  now.realtime_refused = {"pulse"};
  changes.log(before, now);
  changes.log(now, now);
  CHECK(log.count("realtime: the pulse thread was refused SCHED_FIFO at priority 98") == 1);
  PipelineSnapshot both = now;
  both.realtime_refused.emplace_back("capture");
  changes.log(now, both);
  CHECK(log.count("realtime: the capture thread was refused SCHED_FIFO at priority 88") == 1);
  CHECK(log.count("realtime: the pulse thread") == 1);
}
