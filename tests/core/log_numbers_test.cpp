// The log readers on numbers written with thousands separators ("1,200" rpm, as a spreadsheet formats
// them): read where the column says the comma groups digits, a bad row naming its line where it could be a
// decimal comma. tests/core/sample_io_test.cpp, log_formats_test.cpp and log_times_test.cpp hold the
// formats themselves.
#include <catch2/catch.hpp>

#include <string>

#include "core/sample_io.hpp"
#include "tests/core/read_log_text.hpp"

using gearpulse::SampleFileFormat;
using gearpulse::SampleLog;
using gearpulse::test::error_of;
using gearpulse::test::read_log_text;

TEST_CASE("io: quoted digit groups read as their number where the column's other cells are plain numbers") {
  SECTION("named columns: rpm and a time with a decimal point") {
    const SampleLog log = read_log_text(
        "Time,Engine RPM,Speed (km/h)\n998,800,10\n999,\"1,200\",20\n\"1,000.5\",\"12,350.5\",30\n");
    CHECK(log.skipped_count == 0);
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[1].freq == Approx(1200 / 60.0));
    CHECK(log.samples[2].freq == Approx(12350.5 / 60.0));
    CHECK(log.samples[2].t == Approx(2.5));
  }
  SECTION("a generic log, a Torque export, PID rows") {
    const SampleLog generic = read_log_text("t,speed,freq\n0,1,20\n1,2,\"1,020\"\n");
    CHECK(generic.skipped_count == 0);
    REQUIRE(generic.samples.size() == 2);
    CHECK(generic.samples[1].freq == Approx(1020));
    const SampleLog torque = read_log_text(
        "Device Time,GPS Speed (Meters/second),Engine RPM(rpm)\n10:00:00,5,900\n10:00:01,6,\"1,200\"\n");
    CHECK(torque.format == SampleFileFormat::kTorque);
    REQUIRE(torque.samples.size() == 2);
    CHECK(torque.samples[1].freq == Approx(20));
    const SampleLog pids = read_log_text(
        "SECONDS,PID,VALUE,UNITS\n1,Engine RPM,\"1,200\",rpm\n1,Speed,30,km/h\n2,Engine RPM,900,rpm\n"
        "2,Speed,31,km/h\n");
    CHECK(pids.format == SampleFileFormat::kPidRows);
    CHECK(pids.skipped_count == 0);
    REQUIRE(pids.samples.size() == 2);
    CHECK(pids.samples[0].freq == Approx(20));
  }
}

TEST_CASE(
    "io: digit groups that could be a decimal comma, or are no groups, are bad rows naming their line") {
  SECTION("a column whose other cells have decimal commas") {
    const SampleLog log =
        read_log_text("Time,Engine RPM,Speed (km/h)\n0,\"800,5\",10\n1,\"1,200\",20\n2,900,30\n3,950,31\n");
    REQUIRE(log.samples.size() == 2);
    REQUIRE(log.skipped.size() == 2);
    CHECK(log.skipped[0] == "log.csv:2: not a number in column rpm: '800,5'");
    CHECK(log.skipped[1] ==
          "log.csv:3: a thousands separator or a decimal comma? in column rpm: '1,200' (other cells of the "
          "column have decimal commas)");
  }
  SECTION("a column of digit groups alone") {
    const SampleLog log = read_log_text(
        "Time,Engine RPM,Speed (km/h)\n0,\"1,200\",10\n1,\"1,300\",20\n2,\"1,400\",30\n3,,31\n");
    REQUIRE(log.samples.size() == 1);  // a missing cell vouches for nothing
    CHECK(log.skipped_count == 3);
    CHECK(log.skipped[0] ==
          "log.csv:2: a thousands separator or a decimal comma? in column rpm: '1,200' (no other cell of the "
          "column is a number without a comma)");
    CHECK(error_of("t,speed,freq\n0,1,\"1,020\"\n1,2,\"1,030\"\n").find("log.csv:2: a thousands separator") !=
          std::string::npos);
  }
  SECTION("commas that make no groups: not a number, as before") {
    const SampleLog log = read_log_text(
        "t,speed,freq\n0,1,20\n1,1,\"1,20\"\n2,1,\"12,3456\"\n3,1,\"1,2,3\"\n4,1,\",200\"\n"
        "5,1,\"1,200.\"\n6,1,\"1 200\"\n7,1,21\n");
    REQUIRE(log.samples.size() == 2);
    REQUIRE(log.skipped.size() == 6);
    for (const std::string& message : log.skipped)
      CHECK(message.find(": not a number in column freq") != std::string::npos);
  }
}

TEST_CASE("io: where the comma is the decimal mark, point groups read where nothing else can be meant") {
  SECTION("a point with a decimal comma, or more than one point: thousands") {
    const SampleLog log = read_log_text("Time;Engine RPM;Speed (km/h)\n0;800;10\n1;1.200,5;20\n2;900;30\n");
    CHECK(log.skipped_count == 0);
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[1].freq == Approx(1200.5 / 60));
    const SampleLog times = read_log_text("t;speed;freq\n1.000.000;1;20\n1.000.001;2;21\n");
    CHECK(times.skipped_count == 0);
    REQUIRE(times.samples.size() == 2);
    CHECK(times.samples[1].t == Approx(1000001));
  }
  SECTION("one point and three digits: a decimal point as before, but a bad row among decimal commas") {
    const SampleLog point = read_log_text("Time;Engine RPM;Speed (km/h)\n0;800;10\n1;1.200;20\n");
    REQUIRE(point.samples.size() == 2);
    CHECK(point.samples[1].freq == Approx(1.2 / 60));
    const SampleLog commas =
        read_log_text("Time;Engine RPM;Speed (km/h)\n0;800,5;10\n1;1.200;20\n2;900;30\n3;1,200;40\n");
    REQUIRE(commas.samples.size() == 3);
    CHECK(commas.samples[2].freq == Approx(1.2 / 60));  // "1,200" is 1.2 where the comma is the mark
    REQUIRE(commas.skipped.size() == 1);
    CHECK(commas.skipped[0] ==
          "log.csv:3: a thousands separator or a decimal point? in column rpm: '1.200' (other cells of the "
          "column have decimal commas)");
  }
}
