#include <catch2/catch.hpp>

#include <cstdint>
#include <limits>

#include "drivers/gps_report.hpp"

using gearpulse::FixNovelty;
using gearpulse::GpsReport;

namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

GpsReport report(std::int64_t rx_ms, double speed, double fix_time) {
  GpsReport r;
  r.rx_ns = rx_ms * 1'000'000;
  r.speed = speed;
  r.mode = 3;
  r.fix_time = fix_time;
  return r;
}

}  // namespace

TEST_CASE("gps: a fix is measured once, however often its report is seen again", "[gps]") {
  FixNovelty fixes;
  CHECK(fixes.is_new(report(1000, 10.0, 1.7e9)));
  // The same fix polled at the next steps, and sent again by gpsd for another sentence of its epoch.
  CHECK_FALSE(fixes.is_new(report(1000, 10.0, 1.7e9)));
  CHECK_FALSE(fixes.is_new(report(1100, 10.0, 1.7e9)));
  // The receiver's next epoch, at the same speed (a steady cruise).
  CHECK(fixes.is_new(report(2000, 10.0, 1.7e9 + 1.0)));
  CHECK_FALSE(fixes.is_new(report(2000, 10.0, 1.7e9 + 1.0)));
  // A receiver whose clock stands still while the car changes speed.
  CHECK(fixes.is_new(report(3000, 11.0, 1.7e9 + 1.0)));
  CHECK_FALSE(fixes.is_new(report(3050, 11.0, 1.7e9 + 1.0)));
}

TEST_CASE("gps: a report without a receiver time is known by when it arrived", "[gps]") {
  FixNovelty fixes;
  CHECK(fixes.is_new(report(1000, 10.0, kNan)));
  CHECK_FALSE(fixes.is_new(report(1000, 10.0, kNan)));
  CHECK(fixes.is_new(report(2000, 10.0, kNan)));
  // Its receiver time returning, and going again.
  CHECK(fixes.is_new(report(2000, 10.0, 1.7e9)));
  CHECK(fixes.is_new(report(3000, 10.0, kNan)));
  CHECK_FALSE(fixes.is_new(report(3000, 10.0, kNan)));
}

TEST_CASE("gps: the first report is new whatever it holds", "[gps]") {
  FixNovelty at_zero;
  CHECK(at_zero.is_new(report(0, 0.0, kNan)));
  FixNovelty unknown_speed;
  CHECK(unknown_speed.is_new(report(0, kNan, 0.0)));
  CHECK_FALSE(unknown_speed.is_new(report(500, kNan, 0.0)));
}
