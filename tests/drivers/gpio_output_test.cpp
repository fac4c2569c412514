#include <catch2/catch.hpp>

#include <gpiod.h>

#include "drivers/gpio_output.hpp"
#include "drivers/pulse_thread.hpp"

using gearpulse::GpioOutput;

// Hardware tests: they need a GPIO chip (a board, or the gpio-sim kernel module). Without one they say
// that they skipped; the scheduling logic is tested in tests/core without hardware.
namespace {
bool skip_without_chip() {
  if (gearpulse::gpio_chip_available()) return false;
  WARN("GEARPULSE_SKIP: no /dev/gpiochip* on this machine (no GPIO hardware, gpio-sim not loaded)");
  return true;
}
}  // namespace

TEST_CASE("gpio: an unknown chip is a clear error") {
  CHECK_THROWS_WITH(GpioOutput("gpiochip-does-not-exist", 3),
                    Catch::Contains("gpiochip-does-not-exist") && Catch::Contains("cannot open"));
}

TEST_CASE("gpio: the line goes high for a pulse and is left low on close") {
  if (skip_without_chip()) return;
  gpiod_chip* chip = ::gpiod_chip_open_lookup("0");
  REQUIRE(chip);
  const unsigned offset = ::gpiod_chip_num_lines(chip) - 1;
  ::gpiod_chip_close(chip);
  {
    GpioOutput out("0", offset);
    out.rise();
    out.fall();
    CHECK(out.errors() == 0);
    CHECK(out.describe().find("line") != std::string::npos);
  }
  chip = ::gpiod_chip_open_lookup("0");
  gpiod_line* line = ::gpiod_chip_get_line(chip, offset);
  CHECK_FALSE(::gpiod_line_is_used(line));  // released
  ::gpiod_chip_close(chip);
}

TEST_CASE("gpio: a busy line is a clear error naming its user") {
  if (skip_without_chip()) return;
  gpiod_chip* chip = ::gpiod_chip_open_lookup("0");
  REQUIRE(chip);
  const unsigned offset = ::gpiod_chip_num_lines(chip) - 1;
  gpiod_line* line = ::gpiod_chip_get_line(chip, offset);
  REQUIRE(::gpiod_line_request_output(line, "other-user", 0) == 0);
  CHECK_THROWS_WITH(GpioOutput("0", offset), Catch::Contains("busy") && Catch::Contains("other-user"));
  ::gpiod_line_release(line);
  ::gpiod_chip_close(chip);
}

TEST_CASE("gpio: an offset beyond the chip is a clear error") {
  if (skip_without_chip()) return;
  CHECK_THROWS_WITH(GpioOutput("0", 100000), Catch::Contains("out of range"));
}
