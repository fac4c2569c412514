// The journal's lines on the pulse output name it as the status does: the PTY's path or chip:line.
#include <catch2/catch.hpp>

#include "daemon/change_reporter.hpp"
#include "daemon/config.hpp"
#include "tests/daemon/log_lines.hpp"

using gearpulse::daemon::ChangeReporter;
using gearpulse::daemon::Config;
using gearpulse::daemon::OutputKind;
using gearpulse::daemon::OutputState;
using gearpulse::daemon::PipelineSnapshot;

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
