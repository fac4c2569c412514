// ReadOptions::speed_unit (`--speed-unit`): the unit of a speed column whose name states none, in the
// named-column and speed,rpm logs; a column that states its unit (by its name, a units row or its cells)
// keeps it, and the other formats' speeds are not touched. log_formats_test.cpp holds the formats.
#include <catch2/catch.hpp>

#include <cstddef>
#include <string>

#include "core/sample_io.hpp"
#include "tests/core/read_log_text.hpp"

using gearpulse::ReadOptions;
using gearpulse::SampleFileFormat;
using gearpulse::SampleLog;
using gearpulse::speed_unit_named;
using gearpulse::TorqueSpeed;
using gearpulse::test::error_of;
using gearpulse::test::read_log_text;

namespace {

constexpr double kMph = 0.44704;  // m/s per mph (exactly 1609.344 m an hour)

ReadOptions in_unit(const char* name) {
  ReadOptions options;
  options.speed_unit = speed_unit_named(name);
  REQUIRE(options.speed_unit);
  return options;
}

void check_same_samples(const SampleLog& a, const SampleLog& b) {
  REQUIRE(a.samples.size() == b.samples.size());
  for (std::size_t i = 0; i < a.samples.size(); ++i) {
    CHECK(a.samples[i].t == b.samples[i].t);
    CHECK(a.samples[i].speed == b.samples[i].speed);
    CHECK(a.samples[i].freq == b.samples[i].freq);
  }
}

}  // namespace

TEST_CASE("io: the four speed units a user names, and no other spelling") {
  for (const char* name : {"km/h", "mph", "m/s", "knots"}) {
    INFO(name);
    REQUIRE(speed_unit_named(name));
    CHECK(speed_unit_named(name)->name == name);
  }
  CHECK(speed_unit_named("mph")->to_ms == kMph);
  CHECK(speed_unit_named("knots")->to_ms == Approx(1852.0 / 3600.0));
  for (const char* other : {"kph", "MPH", "knot", "km/h ", ""}) {
    INFO(other);
    CHECK_FALSE(speed_unit_named(other));
  }
}

TEST_CASE("io: a named column's speed that states no unit is read in the unit given, refused without it") {
  const std::string rows = "0,800,0\n1,1500,10\n2,2100,20\n";
  const SampleLog given = read_log_text("time,ENGINE_RPM,SPEED\n" + rows, in_unit("mph"));
  CHECK(given.format == SampleFileFormat::kColumns);
  CHECK(given.speed_column == "SPEED");
  CHECK(given.speed_unit == "mph");
  CHECK(given.skipped_count == 0);
  const SampleLog named = read_log_text("time,ENGINE_RPM,SPEED (mph)\n" + rows);
  CHECK(named.speed_unit == "mph");
  check_same_samples(given, named);
  CHECK(given.samples[2].speed == Approx(20 * kMph));
  // Without it: refused, naming the column, the units and the option.
  CHECK(error_of("time,ENGINE_RPM,SPEED\n" + rows) ==
        "log.csv:1: speed column 'SPEED' states no unit: name it with km/h, mph, m/s or knots, or pass "
        "--speed-unit");
  // --speed gps takes a GPS column that states no unit before an OBD one that does.
  ReadOptions gps = in_unit("knots");
  gps.torque_speed = TorqueSpeed::kGps;
  const SampleLog from_gps = read_log_text("time,rpm,OBD speed (km/h),GPS speed\n0,800,9,10\n", gps);
  CHECK(from_gps.speed_column == "GPS speed");
  REQUIRE(from_gps.samples.size() == 1);
  CHECK(from_gps.samples[0].speed == Approx(10 * 1852.0 / 3600.0));
}

TEST_CASE("io: a speed column that states its unit keeps it, whatever unit is given") {
  const ReadOptions mph = in_unit("mph");
  // By its name; a column that states one is taken before one that does not.
  for (const std::string text : {"time,rpm,Speed (km/h)\n0,800,0\n1,1500,18\n",
                                 "time,ENGINE_RPM,SPEED,Speed (km/h)\n0,800,7,0\n1,1500,11,18\n"}) {
    INFO(text);
    const SampleLog log = read_log_text(text, mph);
    CHECK(log.speed_column == "Speed (km/h)");
    CHECK(log.speed_unit == "km/h");
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].speed == Approx(5.0));
  }
  // By a units row under the header: the row is the header's, no bad row.
  const SampleLog units_row =
      read_log_text("Time,Engine RPM,Vehicle speed\ns,rpm,km/h\n0,800,0\n1,1500,18\n", mph);
  CHECK(units_row.speed_unit == "km/h");
  CHECK(units_row.skipped_count == 0);
  REQUIRE(units_row.samples.size() == 2);
  CHECK(units_row.samples[1].speed == Approx(5.0));
  // By its cells, as python-OBD writes them.
  const SampleLog cells = read_log_text(
      "timestamp,RPM,SPEED\n"
      "2025-04-11 18:13:28,790.5 revolutions_per_minute,0.0 kilometer_per_hour\n"
      "2025-04-11 18:13:30,1511.0 revolutions_per_minute,18.0 kilometer_per_hour\n",
      mph);
  CHECK(cells.speed_unit == "km/h");
  REQUIRE(cells.samples.size() == 2);
  CHECK(cells.samples[1].speed == Approx(5.0));
}

TEST_CASE("io: a speed,rpm log is read in the unit given, not the one its values suggest") {
  // Whole km/h converted to mph, as a logger writes them: mph by their values, km/h when told.
  std::string text = "rpm,speed\n";
  for (int k = 1; k <= 12; ++k)
    text += std::to_string(800 + 150 * k) + "," + std::to_string(k * 7 / 1.609344) + "\n";
  CHECK(read_log_text(text).speed_unit == "mph");
  const SampleLog kmh = read_log_text(text, in_unit("km/h"));
  CHECK(kmh.format == SampleFileFormat::kSpeedRpm);
  CHECK(kmh.speed_unit == "km/h");
  REQUIRE(kmh.samples.size() == 12);
  CHECK(kmh.samples[1].speed == Approx(14 / 1.609344 / 3.6));
  // Whole numbers, km/h by their values: mph when told.
  const SampleLog mph = read_log_text("rpm,speed\n900,7\n1050,14\n", in_unit("mph"));
  CHECK(mph.speed_unit == "mph");
  REQUIRE(mph.samples.size() == 2);
  CHECK(mph.samples[1].speed == Approx(14 * kMph));
}

TEST_CASE("io: the generic log's speed stays m/s, and a Carloop log's km/h, whatever unit is given") {
  const SampleLog generic = read_log_text("t,speed,freq\n0,10,30\n1,12,35\n", in_unit("mph"));
  CHECK(generic.format == SampleFileFormat::kGeneric);
  REQUIRE(generic.samples.size() == 2);
  CHECK(generic.samples[1].speed == 12.0);
  const SampleLog carloop = read_log_text(
      "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED (),\n24, 1200, 36,\n25, 1500, 45,\n", in_unit("mph"));
  CHECK(carloop.format == SampleFileFormat::kCarloop);
  REQUIRE(carloop.samples.size() == 2);
  CHECK(carloop.samples[1].speed == Approx(12.5));
}
