// The log readers on other apps' formats: Carloop, speed and rpm, Torque, named columns, PID rows.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/sample_io.hpp"
#include "tests/core/read_log_text.hpp"

using gearpulse::SampleFileFormat;
using gearpulse::SampleLog;
using gearpulse::test::error_of;
using gearpulse::test::read_log_text;

TEST_CASE("io: an outage row repeating the held rpm within a polling round and a half brings nothing") {
  using gearpulse::kMissing;
  using gearpulse::repeats_held_freq;
  const gearpulse::Sample stepped{100.0, 12.0, 25.0};
  // Within kHeldSpan of the last sample stepped, the same rpm without a speed is a held copy.
  CHECK(repeats_held_freq(stepped, {100.5, kMissing, 25.0}));
  CHECK(repeats_held_freq(stepped, {100.0 + gearpulse::kHeldSpan, kMissing, 25.0}));
  // Later, it is a reading again: an engine that keeps one value (switched off, 0 rpm) is not frozen out.
  CHECK_FALSE(repeats_held_freq(stepped, {100.1 + gearpulse::kHeldSpan, kMissing, 25.0}));
  CHECK_FALSE(repeats_held_freq({100.0, kMissing, 0.0}, {130.0, kMissing, 0.0}));
  // A new value, a row with a speed (GPS brings a reading) or no frequency at all are stepped.
  CHECK_FALSE(repeats_held_freq(stepped, {100.5, kMissing, 25.1}));
  CHECK_FALSE(repeats_held_freq(stepped, {100.5, 12.5, 25.0}));
  CHECK_FALSE(repeats_held_freq({100.0, kMissing, kMissing}, {100.5, kMissing, kMissing}));
}

TEST_CASE("io: Carloop rows that refresh nothing are dropped and rpm becomes Hz") {
  const std::string header = "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED (),THROTTLE (),\r\n";
  const SampleLog log = read_log_text(header +
                                      "24.000000, 873.250000, 3.000000, 17.6,\r\n"
                                      "25.000000, 873.250000, 3.000000, 17.6,\r\n"
                                      "25.000000, 873.250000, 3.000000, 17.9,\r\n"
                                      "27.000000, 1200.000000, 18.000000, 17.6,\r\n"
                                      "27.000000, 1200.000000, 18.000000, 17.6,\r\n");
  CHECK(log.format == SampleFileFormat::kCarloop);
  REQUIRE(log.samples.size() == 2);
  CHECK(log.repeated_rows == 3);
  CHECK(log.samples[0].t >= 24.0);
  CHECK(log.samples[0].t <= 25.0);
  CHECK(log.samples[1].t > log.samples[0].t);
  CHECK(log.samples[0].freq == Approx(873.25 / 60));
  CHECK(log.samples[1].speed == Approx(18 / 3.6));
}

TEST_CASE("io: with keep_rows every accepted row is kept in order, a repeat with the sample it repeats") {
  // A Carloop log with uneven rows (the logger stalls for seconds now and then), values refreshed every
  // few rows; one refreshed row is bad (a speed beyond any road vehicle) and so are the rows repeating it.
  std::string text = "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED (),THROTTLE (),\n";
  std::uint64_t state = 7;
  const auto next = [&] {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    return static_cast<int>((state >> 33) % 1000);
  };
  double counter = 0.0;
  int refresh = 0;
  std::size_t rows = 0, bad_rows = 0;
  for (int i = 0; i < 2000; ++i) {
    counter += next() < 30 ? 2.0 + next() % 8 : 0.5;  // mostly two rows a second, sometimes a stall
    if (next() < 300) ++refresh;
    const bool bad = refresh == 40;
    char row[128];
    std::snprintf(row, sizeof row, "%d.000000, %d.000000, %d.000000, 17.6,\n", static_cast<int>(counter),
                  1000 + 10 * (refresh % 50), bad ? 900 : 20 + refresh % 30);
    text += row;
    bad ? ++bad_rows : ++rows;
  }
  gearpulse::ReadOptions keep;
  keep.keep_rows = true;
  const SampleLog log = read_log_text(text, keep);
  REQUIRE(bad_rows > 0);
  CHECK(log.rows.size() == rows);
  CHECK(log.skipped_count == bad_rows);
  CHECK(log.repeated_rows > 0);
  bool ordered = true, repeats_share = true;
  for (std::size_t i = 1; i < log.rows.size(); ++i) {
    ordered = ordered && log.rows[i].t >= log.rows[i - 1].t;
    repeats_share = repeats_share && (log.rows[i].sample == log.rows[i - 1].sample ||
                                      log.rows[i].sample == log.rows[i - 1].sample + 1);
  }
  CHECK(ordered);
  CHECK(repeats_share);
  CHECK(log.rows.back().sample == log.samples.size() - 1);
  // Without keep_rows, the same samples.
  const SampleLog plain = read_log_text(text);
  CHECK(plain.rows.empty());
  REQUIRE(plain.samples.size() == log.samples.size());
  for (std::size_t i = 0; i < plain.samples.size(); ++i)
    CHECK(plain.samples[i].t == log.samples[i].t);
}

TEST_CASE("io: Carloop row times are recovered below the counter's one-second step") {
  // Rows every 0.49 s; the whole-second run-time counter is refreshed every fourth row, rpm changes on
  // every fourth row too but two rows later (a different PID in the round-robin).
  std::string text = "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED (),\r\n";
  std::vector<double> truth;
  double counter = 0.0, rpm = 0.0;
  for (int row = 0; row < 400; ++row) {
    const double t = 0.49 * row;
    if (row % 4 == 0) counter = std::floor(t);
    if (row % 4 == 2) {
      rpm = 1000.0 + row;
      truth.push_back(t);
    }
    text += std::to_string(counter) + ", " + std::to_string(rpm) + ", 30.000000,\r\n";
  }
  const SampleLog log = read_log_text(text);
  REQUIRE(log.samples.size() == truth.size() + 1);  // plus the first row (rpm 0)
  std::vector<double> errors;
  for (std::size_t i = 0; i < truth.size(); ++i)
    errors.push_back(std::abs(log.samples[i + 1].t - truth[i]));
  std::sort(errors.begin(), errors.end());
  CHECK(errors[errors.size() / 2] < 0.2);  // the raw counter is off by 0.5 s on average
  CHECK(errors.back() < 0.6);
}

TEST_CASE("io: speed and rpm logs use the row counter as time") {
  const SampleLog log = read_log_text("speed,rpm,load\n7,898,44\n7,898,44\n1,917,32\n");
  CHECK(log.format == SampleFileFormat::kSpeedRpm);
  REQUIRE(log.samples.size() == 2);
  CHECK(log.samples[0].t == Approx(0));
  CHECK(log.samples[1].t == Approx(2));
  CHECK(log.samples[1].speed == Approx(1 / 3.6));
  CHECK(log.samples[1].freq == Approx(917.0 / 60));
  CHECK(log.time_from_rows);
}

TEST_CASE("io: a speed and rpm log with a time column takes its times from it") {
  const SampleLog log = read_log_text("time,speed,rpm\n10.0,7,898\n10.5,7,898\n11.0,1,917\n");
  CHECK(log.format == SampleFileFormat::kSpeedRpm);
  CHECK_FALSE(log.time_from_rows);
  REQUIRE(log.samples.size() == 2);
  CHECK(log.samples[1].t == Approx(1.0));
  CHECK(log.samples[1].speed == Approx(1 / 3.6));
  const SampleLog ms = read_log_text("rpm,speed,Time (ms)\n898,7,5000\n917,1,5250\n");
  REQUIRE(ms.samples.size() == 2);
  CHECK(ms.samples[1].t == Approx(0.25));
  const SampleLog clock = read_log_text("Time,speed,rpm\n10:59:59.5,7,898\n11:00:00.0,1,917\n");
  REQUIRE(clock.samples.size() == 2);
  CHECK(clock.samples[1].t == Approx(0.5));
}

TEST_CASE("io: a speed and rpm log whose speeds are whole km/h in mph or m/s is read in that unit") {
  // A logger that converts the OBD speed (whole km/h) writes k * 0.621371 mph (or k / 3.6 m/s); ts is a
  // time column (milliseconds since 1970, as its values reach 1e11).
  std::string mph = "ts,rpm,speed\n", ms = "rpm,speed\n", kmh = "rpm,speed\n", few = "rpm,speed\n";
  for (int k = 1; k <= 12; ++k) {
    const int rpm = 800 + 150 * k;
    mph += std::to_string(1558525279922LL + 1400 * k) + "," + std::to_string(rpm) + "," +
           std::to_string(k * 7 / 1.609344) + "\n";
    ms += std::to_string(rpm) + "," + std::to_string(k * 7 / 3.6) + "\n";
    kmh += std::to_string(rpm) + "," + std::to_string(k * 7) + "\n";
    if (k <= 5) few += std::to_string(rpm) + "," + std::to_string(k * 7 / 1.609344) + "\n";
  }
  const SampleLog in_mph = read_log_text(mph);
  CHECK(in_mph.format == SampleFileFormat::kSpeedRpm);
  CHECK(in_mph.speed_unit == "mph");
  CHECK_FALSE(in_mph.time_from_rows);
  REQUIRE(in_mph.samples.size() == 12);
  CHECK(in_mph.samples[1].t == 1.4);  // counted in whole milliseconds: exact, as replay prints it
  CHECK(in_mph.samples[1].speed == Approx(14 / 3.6).epsilon(1e-4));
  const SampleLog in_ms = read_log_text(ms);
  CHECK(in_ms.speed_unit == "m/s");
  CHECK(in_ms.samples[1].speed == Approx(14 / 3.6).epsilon(1e-4));
  // Whole numbers are km/h themselves, and too few values say nothing: km/h.
  const SampleLog in_kmh = read_log_text(kmh);
  CHECK(in_kmh.speed_unit == "km/h");
  CHECK(in_kmh.samples[1].speed == Approx(14 / 3.6));
  CHECK(read_log_text(few).speed_unit == "km/h");
  // Speeds in mph as measured (not whole km/h) stay km/h, said in the note.
  std::string measured = "rpm,speed\n";
  for (int k = 1; k <= 12; ++k)
    measured += std::to_string(900 + 150 * k) + "," + std::to_string(4.37 * k + 0.13) + "\n";
  CHECK(read_log_text(measured).speed_unit == "km/h");
  // Highway speeds in km/h at one decimal are not a whole km/h in m/s (m/s is km/h / 3.6 exactly).
  std::string highway = "rpm,speed\n";
  for (const double v : {95.9, 98.3, 101.7, 104.2, 107.6, 110.1, 113.8, 116.4, 119.9, 122.5, 126.0, 129.2})
    highway += std::to_string(static_cast<int>(30 * v)) + "," + std::to_string(v) + "\n";
  CHECK(read_log_text(highway).speed_unit == "km/h");
}

TEST_CASE("io: a named log's seconds since 1970 count from its first in the digits written") {
  // Seconds since 1970 with decimals, as python's time.time() writes them: 1558525281.521 - 1558525279.922
  // in doubles is 1.5989999771118164; the times keep the milliseconds written. The first row is bad (NaN).
  const SampleLog epoch = read_log_text(
      "timestamp,RPM,SPEED (km/h)\n1558525278.5,700,NaN\n1558525279.922,800,10\n1558525281.521,900,11\n"
      "1558525283.12,1000,12\n");
  REQUIRE(epoch.samples.size() == 3);
  CHECK(epoch.samples[0].t == 0.0);
  CHECK(epoch.samples[1].t == 1.599);
  CHECK(epoch.samples[2].t == 3.198);
  // In milliseconds with decimals, and times from 0, exactly as written.
  const SampleLog ms =
      read_log_text("time (ms),rpm,speed (km/h)\n0,800,10\n1599.5,900,11\n3198.25,1000,12\n");
  REQUIRE(ms.samples.size() == 3);
  CHECK(ms.samples[1].t == 1599.5 * 1e-3);
  CHECK(ms.samples[2].t == 3198.25 * 1e-3);
  const SampleLog from_zero = read_log_text("time,rpm,speed (km/h)\n0,800,10\n0.1,900,11\n0.3,1000,12\n");
  CHECK(from_zero.samples[1].t == 0.1);
  CHECK(from_zero.samples[2].t == 0.3);
}

TEST_CASE("io: a time too small for a log counted in milliseconds since 1970 is a bad row") {
  const SampleLog log = read_log_text(
      "ts,rpm,speed (km/h)\n1558525279922,1500,20\n1558525281521,1600,21\n3,1700,22\n"
      "1558525283120,1800,23\n");
  REQUIRE(log.samples.size() == 3);
  CHECK(log.samples[2].t == Approx(3.198));
  REQUIRE(log.skipped_count == 1);
  CHECK(log.skipped[0].find(":4: time 3 is not milliseconds since 1970") != std::string::npos);
}

TEST_CASE("io: readings written with their units, as python-OBD writes them, read with those units") {
  // SPEED names no unit; its cells do: a named-column log in km/h, its rpm cells read as numbers.
  const SampleLog kmh = read_log_text(
      "timestamp,RPM,SPEED,COOLANT_TEMP\n"
      "2025-04-11 18:13:28,790.5 revolutions_per_minute,0.0 kilometer_per_hour,93 degree_Celsius\n"
      "2025-04-11 18:13:30,1511.0 revolutions_per_minute,12.0 kilometer_per_hour,93 degree_Celsius\n");
  CHECK(kmh.format == SampleFileFormat::kColumns);
  CHECK(kmh.speed_column == "SPEED");  // the name written, its unit stated in its cells
  CHECK(kmh.speed_unit == "km/h");
  CHECK(kmh.speed_unit_stated_in == "its cells");
  REQUIRE(kmh.samples.size() == 2);
  CHECK(kmh.samples[1].t == Approx(2.0));
  CHECK(kmh.samples[1].speed == Approx(12 / 3.6));
  CHECK(kmh.samples[1].freq == Approx(1511.0 / 60));
  // Converted to mph by the logger; a cell in another unit than its column's is a bad row.
  const SampleLog mph = read_log_text(
      "time,Engine RPM,Vehicle Speed\n0,800.0 revolutions_per_minute,10.0 mile_per_hour\n"
      "1,900.0 revolutions_per_minute,12.0 kilometer_per_hour\n2,1000.0 revolutions_per_minute,11 "
      "mile_per_hour\n");
  CHECK(mph.speed_column == "Vehicle Speed");
  CHECK(mph.speed_unit == "mph");
  REQUIRE(mph.samples.size() == 2);
  CHECK(mph.samples[1].speed == Approx(11 * 0.44704));
  REQUIRE(mph.skipped_count == 1);
  CHECK(mph.skipped[0].find(":3: not a number in column speed") != std::string::npos);
  // A speed,rpm log without units in its cells reads its bare speed as km/h.
  CHECK(read_log_text("speed,rpm\n7,898\n1,917\n").format == SampleFileFormat::kSpeedRpm);
}

TEST_CASE("io: a first row without a speed leaves the speed's unit to the first row that writes one") {
  // python-OBD loggers write None or N/A for a reading the car did not answer.
  const SampleLog mph = read_log_text(
      "timestamp,RPM,SPEED\n0,790.5 revolutions_per_minute,None\n1,1500.0 revolutions_per_minute,12.0 "
      "mile_per_hour\n2,1600.0 revolutions_per_minute,13.0 mile_per_hour\n");
  CHECK(mph.format == SampleFileFormat::kColumns);
  CHECK(mph.speed_unit == "mph");
  REQUIRE(mph.samples.size() == 3);  // None is a missing reading: the row is kept without its speed
  CHECK(std::isnan(mph.samples[0].speed));
  CHECK(mph.samples[0].has_freq());
  CHECK(mph.samples[1].speed == Approx(12 * 0.44704));
  CHECK(mph.skipped_count == 0);
  const SampleLog kmh = read_log_text(
      "timestamp,RPM,Vehicle Speed\n0,790.5 revolutions_per_minute,N/A\n1,N/A,N/A\n"
      "2,1500.0 revolutions_per_minute,12.0 kilometer_per_hour\n");
  CHECK(kmh.speed_unit == "km/h");
  REQUIRE(kmh.samples.size() == 3);
  CHECK(std::isnan(kmh.samples[0].speed));
  CHECK(kmh.samples[2].speed == Approx(12 / 3.6));
  CHECK(kmh.skipped_count == 0);
  // A bare number first: the column states no unit, as in a log without any.
  CHECK(error_of("timestamp,RPM,Vehicle Speed\n0,800,N/A\n1,900,12\n2,1000,12.0 kilometer_per_hour\n")
            .find("'Vehicle Speed' states no unit") != std::string::npos);
  // The look-ahead is bounded: a speed first written after it is no unit of the column.
  std::string late = "timestamp,RPM,Vehicle Speed\n";
  for (int i = 0; i < 100; ++i)
    late += std::to_string(i) + ",800.0 revolutions_per_minute,N/A\n";
  CHECK(error_of(late + "100,900.0 revolutions_per_minute,12.0 kilometer_per_hour\n")
            .find("'Vehicle Speed' states no unit") != std::string::npos);
}

TEST_CASE("io: row_seconds is the row counter's unit in logs without a time column, and only there") {
  gearpulse::ReadOptions options;
  options.row_seconds = 0.5;
  options.keep_rows = true;
  const SampleLog rows = read_log_text("speed,rpm\n7,898\n7,898\n1,917\n3,1200\n", options);
  CHECK(rows.time_from_rows);
  REQUIRE(rows.samples.size() == 3);
  CHECK(rows.samples[1].t == Approx(1.0));
  CHECK(rows.samples[2].t == Approx(1.5));
  REQUIRE(rows.rows.size() == 4);
  CHECK(rows.rows[1].t == Approx(0.5));  // a repeated row keeps its own time
  // A log with its own times keeps them.
  const SampleLog timed = read_log_text("t,speed,freq\n0,1,50\n3,1,50\n", options);
  CHECK_FALSE(timed.time_from_rows);
  REQUIRE(timed.samples.size() == 2);
  CHECK(timed.samples[1].t == Approx(3.0));
  const SampleLog carloop = read_log_text(
      "ENGINE_RUN_TINE (), ENGINE_RPM (), VEHICLE_SPEED (),\n4, 900, 0,\n5, 1800, 20,\n", options);
  CHECK_FALSE(carloop.time_from_rows);
  REQUIRE(carloop.samples.size() == 2);
  CHECK(carloop.samples[0].t >= 4.0);  // its run-time counter, not the row counter
  for (const double bad : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    options.row_seconds = bad;
    CHECK_THROWS_AS(read_log_text("speed,rpm\n7,898\n", options), std::invalid_argument);
  }
}

TEST_CASE("io: Torque exports pick GPS or OBD speed and unwrap the clock") {
  const std::string text =
      "GPS Time, Device Time,GPS Speed (Meters/second),Engine RPM(rpm),Speed (OBD)(mph),Ratio\n"
      "Thu Jan 11 19:59:58 EST 2018,59:58.5,10,2000,22,#DIV/0!\n"
      "-,59:59.5,-,2100,23,#N/A\n"
      "Thu Jan 11 20:00:00 EST 2018,00:00.5,11,-,24,\n";
  const SampleLog gps = read_log_text(text);
  CHECK(gps.format == SampleFileFormat::kTorque);
  CHECK(gps.speed_column == "GPS Speed (Meters/second)");
  REQUIRE(gps.samples.size() == 3);
  CHECK(gps.samples[0].t == Approx(0));
  CHECK(gps.samples[2].t == Approx(2));
  CHECK(gps.samples[0].speed == Approx(10));
  CHECK_FALSE(gps.samples[1].has_speed());
  CHECK(gps.samples[1].freq == Approx(35));
  CHECK_FALSE(gps.samples[2].has_freq());

  gearpulse::ReadOptions obd;
  obd.torque_speed = gearpulse::TorqueSpeed::kObd;
  const SampleLog log = read_log_text(text, obd);
  CHECK(log.speed_column == "Speed (OBD)(mph)");
  CHECK(log.samples[1].speed == Approx(23 * 0.44704));
}

TEST_CASE("io: Torque's column names are read whatever their spacing, GPS speed in mph or km/h") {
  const SampleLog mph = read_log_text(
      "Device Time, Engine RPM (rpm), Speed (GPS)(mph)\n"
      "10:00.0,1200,10\n10:01.0,1300,20\n");
  CHECK(mph.format == SampleFileFormat::kTorque);
  CHECK(mph.speed_column == "Speed (GPS)(mph)");
  REQUIRE(mph.samples.size() == 2);
  CHECK(mph.samples[1].speed == Approx(20 * 0.44704));
  CHECK(mph.samples[1].freq == Approx(1300.0 / 60));

  const SampleLog kmh = read_log_text(
      "GPS Time,Engine RPM(rpm),GPS Speed(km/h)\n"
      "Thu Jan 11 19:59:58 EST 2018,1200,36\n");
  CHECK(kmh.speed_column == "GPS Speed (km/h)");
  REQUIRE(kmh.samples.size() == 1);
  CHECK(kmh.samples[0].speed == Approx(10));
}

TEST_CASE("io: another app's log is read by its column names: rpm, speed with a unit, a time") {
  SECTION("an OBD data set's export: a clock, km/h, held values dropped") {
    const SampleLog log = read_log_text(
        "Time,Engine Coolant Temperature [C],Engine RPM [RPM],Vehicle Speed Sensor [km/h]\n"
        "10:56:25.5,80,1800,36\n10:56:25.6,80,1800,36\n10:56:26.25,80,2400,45\n");
    CHECK(log.format == SampleFileFormat::kColumns);
    CHECK(log.speed_column == "Vehicle Speed Sensor [km/h]");
    CHECK(log.repeated_rows == 1);
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[0].t == Approx(0));
    CHECK(log.samples[1].t == Approx(0.75));
    CHECK(log.samples[1].speed == Approx(12.5));
    CHECK(log.samples[1].freq == Approx(40));
  }
  SECTION("a clock passing midnight runs on") {
    const SampleLog log = read_log_text("time,rpm,speed (mph)\n23:59:59,1200,10\n00:00:01,1300,20\n");
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].t == Approx(2));
    CHECK(log.samples[1].speed == Approx(20 * 0.44704));
  }
  SECTION("seconds, milliseconds stated or since 1970") {
    CHECK(read_log_text("Time (s),RPM,Speed (m/s)\n5,600,1\n6.5,660,2\n").samples[1].t == Approx(1.5));
    CHECK(read_log_text("time_ms,engine_rpm,speed_kmh\n5000,600,1\n6500,660,2\n").samples[1].t ==
          Approx(1.5));
    CHECK(read_log_text("timestamp,rpm,speed kph\n1557132000000,600,1\n1557132001500,660,2\n").samples[1].t ==
          Approx(1.5));
  }
  SECTION("a GPS speed unless --speed obd; no time column: the row counter") {
    const std::string text = "Engine RPM,OBD Speed (km/h),GPS Speed (m/s)\n1200,36,9\n1500,45,12\n";
    const SampleLog gps = read_log_text(text);
    CHECK(gps.speed_column == "GPS Speed (m/s)");
    CHECK(gps.time_from_rows);
    REQUIRE(gps.samples.size() == 2);
    CHECK(gps.samples[1].t == Approx(1));
    CHECK(gps.samples[1].speed == Approx(12));
    gearpulse::ReadOptions obd;
    obd.torque_speed = gearpulse::TorqueSpeed::kObd;
    CHECK(read_log_text(text, obd).samples[1].speed == Approx(12.5));
  }
  SECTION("a speed without a unit is refused, naming the column") {
    CHECK(error_of("Time,Engine RPM,Speed\n1,800,0\n") ==
          "log.csv:1: speed column 'Speed' states no unit: name it with km/h, mph, m/s or knots, or pass "
          "--speed-unit");
  }
}

TEST_CASE("io: a phone app's log of one reading per row: each rpm with the speed at its time") {
  const std::string text =
      "\"SECONDS\";\"PID\";\"VALUE\";\"UNITS\";\"LATITUDE\";\"LONGTITUDE\";\n"
      "\"86399.0\";\"Engine RPM\";\"1200\";\"rpm\";\"\";\"\";\n"
      "\"86399.2\";\"Fuel trim\";\"-3,5\";\"%\";\"\";\"\";\n"
      "\"86399.5\";\"Speed (GPS)\";\"20\";\"mph\";\"\";\"\";\n"
      "\"86399.6\";\"Average speed (GPS)\";\"90\";\"km/h\";\"\";\"\";\n"
      "\"86399.7\";\"Vehicle speed\";\"36\";\"km/h\";\"\";\"\";\n"
      "\"0.5\";\"Engine RPM\";\"1500\";\"rpm\";\"\";\"\";\n"
      "\"0.7\";\"Engine RPM\";\"x\";\"rpm\";\"\";\"\";\n"
      "\"1.5\";\"Speed (GPS)\";\"30\";\"mph\";\"\";\"\";\n"
      "\"2.7\";\"Vehicle speed\";\"54\";\"km/h\";\"\";\"\";\n"
      "\"20\";\"Engine RPM\";\"900\";\"rpm\";\"\";\"\";\n";
  const SampleLog gps = read_log_text(text);
  CHECK(gps.format == SampleFileFormat::kPidRows);
  CHECK(gps.speed_column == "Speed (GPS)");
  REQUIRE(gps.samples.size() == 3);
  CHECK(gps.samples[0].t == Approx(0));  // 86399.0: no speed read before it
  CHECK_FALSE(gps.samples[0].has_speed());
  CHECK(gps.samples[0].freq == Approx(20));
  CHECK(gps.samples[1].t == Approx(1.5));  // past midnight, between the GPS readings 2 s apart
  CHECK(gps.samples[1].speed == Approx(25 * 0.44704));
  CHECK(gps.samples[1].freq == Approx(25));
  CHECK_FALSE(gps.samples[2].has_speed());  // no speed read after it
  REQUIRE(gps.skipped.size() == 1);         // the bad rpm, not the negative fuel trim
  CHECK(gps.skipped[0].rfind("log.csv:8: not a number", 0) == 0);

  gearpulse::ReadOptions obd;
  obd.torque_speed = gearpulse::TorqueSpeed::kObd;
  const SampleLog wheel = read_log_text(text, obd);
  REQUIRE(wheel.samples.size() == 3);
  CHECK(wheel.samples[1].speed == Approx((36 + 18 * 0.8 / 3) / 3.6));

  CHECK(error_of("SECONDS;PID;VALUE;UNITS\n1;Engine RPM;800;rpm\n").find("no speed among the PIDs") !=
        std::string::npos);
}

TEST_CASE("io: named columns and PID rows: units, corrupt clocks and times, summaries, repeated polls") {
  SECTION("kmph is km/h, not mph") {
    CHECK(read_log_text("time,rpm,Speed (kmph)\n0,800,36\n1,900,45\n").samples[1].speed == Approx(12.5));
  }
  SECTION("a clock cell off its neighbours costs its row, not an hour on every later row") {
    const SampleLog log = read_log_text(
        "time,rpm,speed km/h\n10:01,800,1\n10:02,900,2\n45:00,1000,3\n"
        "10:04,1100,4\n10:05,1200,5\n");
    REQUIRE(log.samples.size() == 4);
    CHECK(log.samples[3].t == Approx(4));  // mm:ss
    CHECK(log.skipped_count == 1);
  }
  SECTION("a clock cell among numbers, or a number among clocks, is the bad one") {
    const SampleLog numbers =
        read_log_text("time,rpm,speed km/h\n0,800,1\n1,900,2\n12:30,1000,3\n3,1100,4\n");
    CHECK(numbers.samples.size() == 3);
    CHECK(numbers.skipped_count == 1);
    const SampleLog clocks =
        read_log_text("time,rpm,speed km/h\n10:01,800,1\n5,900,2\n10:03,1000,3\n10:04,1100,4\n");
    CHECK(clocks.samples.size() == 3);
    CHECK(clocks.skipped_count == 1);
  }
  SECTION("a first clock cell away from the rows after it is the bad one") {
    const SampleLog log =
        read_log_text("time,rpm,speed km/h\n45:00,800,1\n10:01,900,2\n10:02,1000,3\n10:03,1100,4\n");
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[2].t == Approx(2));
    CHECK(log.skipped_count == 1);
  }
  SECTION("an average rpm is not the engine's") {
    CHECK(read_log_text("time,Average RPM,Engine RPM,speed km/h\n0,1500,900,1\n").samples[0].freq ==
          Approx(15));
  }
  SECTION("a first row whose time is bad: the times count from the first row kept") {
    const SampleLog log = read_log_text("time,rpm,speed km/h\n900,800,1\n1,900,2\n2,1000,3\n3,1100,4\n");
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[0].t == Approx(0));
    CHECK(log.samples[2].t == Approx(2));
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].find("time 900") != std::string::npos);
  }
  SECTION("an average or maximum speed is not the car's") {
    const SampleLog log = read_log_text("time,Average speed (km/h),rpm,Speed (km/h)\n0,50,800,36\n");
    CHECK(log.speed_column == "Speed (km/h)");
    CHECK(log.samples[0].speed == Approx(10));
  }
  SECTION("a PID reading without a unit has its PID's; each rpm poll is a sample") {
    const SampleLog log = read_log_text(
        "SECONDS;PID;VALUE;UNITS\n0;Vehicle speed;36;\n1;Engine RPM;800;rpm\n2;Engine RPM;800;rpm\n"
        "2.5;Vehicle speed;36;km/h\n"
        "3;Vehicle speed;36;\n4;Engine RPM;800;rpm\n5;Vehicle speed;36;km/h\n");
    REQUIRE(log.samples.size() == 3);
    CHECK(log.repeated_rows == 0);
    CHECK(log.samples[2].speed == Approx(10));
    CHECK(log.samples[1].speed == Approx(10));
  }
}

TEST_CASE("io: the wheel speed of a Torque export read from GPS, row for row, and of nothing else") {
  const std::string both =
      "GPS Time, Device Time,GPS Speed (Meters/second),Engine RPM(rpm),Speed (OBD)(mph)\n"
      "Thu Jan 11 19:59:58 EST 2018,59:58.5,10,2000,22\n"
      "Thu Jan 11 19:59:59 EST 2018,59:59.5,11,2100,24\n";
  const SampleLog gps = read_log_text(both);
  std::istringstream again(both);
  const std::optional<SampleLog> wheel = gearpulse::read_wheel_speed(again, gps);
  REQUIRE(wheel);
  CHECK(wheel->speed_column == "Speed (OBD)(mph)");
  REQUIRE(wheel->samples.size() == gps.samples.size());
  CHECK(wheel->samples[1].t == gps.samples[1].t);
  CHECK(wheel->samples[1].speed == Approx(24 * 0.44704));
  // Read from the OBD speed already, no OBD column, or not a Torque export: nothing.
  gearpulse::ReadOptions obd;
  obd.torque_speed = gearpulse::TorqueSpeed::kObd;
  std::istringstream third(both);
  CHECK_FALSE(gearpulse::read_wheel_speed(third, read_log_text(both, obd)));
  const std::string gps_only =
      "GPS Time, Device Time,GPS Speed (Meters/second),Engine RPM(rpm)\n"
      "Thu Jan 11 19:59:58 EST 2018,59:58.5,10,2000\n";
  std::istringstream in_gps_only(gps_only);
  CHECK_FALSE(gearpulse::read_wheel_speed(in_gps_only, read_log_text(gps_only)));
  const std::string generic = "t,speed,freq\n0,10,30\n";
  std::istringstream in_generic(generic);
  CHECK_FALSE(gearpulse::read_wheel_speed(in_generic, read_log_text(generic)));
}
