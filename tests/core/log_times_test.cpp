// The log readers on times: a corrupt time costs its row alone; clocks that wrap, jump, or carry a zone.
#include <catch2/catch.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "core/sample_io.hpp"
#include "tests/core/read_log_text.hpp"

using gearpulse::SampleFileFormat;
using gearpulse::SampleLog;
using gearpulse::test::read_log_text;

TEST_CASE("io: one row whose time jumps ahead of its neighbours is the bad row, not all that follow") {
  const SampleLog log = read_log_text(
      "t,speed,freq\n"
      "1,10,50\n"
      "2,10,50\n"
      "1e9,10,50\n"
      "3,10,50\n"
      "4,10,50\n"
      "2.5,10,50\n"
      "5,10,50\n");
  REQUIRE(log.samples.size() == 5);
  CHECK(log.samples[2].t == Approx(3));
  CHECK(log.samples[4].t == Approx(5));
  REQUIRE(log.skipped.size() == 2);
  CHECK(log.skipped[0].rfind("log.csv:4: time 1e+09 is ahead of the rows around it", 0) == 0);
  // A row that goes back behind the row before it and the one before that is the bad one itself.
  CHECK(log.skipped[1].rfind("log.csv:7: time goes backwards", 0) == 0);
}

TEST_CASE("io: a corrupt time in the first row or in an OBD log costs that row, not the rows after it") {
  const auto one_skip = [](const SampleLog& log, const std::string& message) {
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind(message, 0) == 0);
  };
  SECTION("the first row of a generic log") {
    const SampleLog log = read_log_text("t,speed,freq\n99999,10,50\n1,10,50\n2,10,50\n3,10,50\n");
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[0].t == Approx(1));
    one_skip(log, "log.csv:2: time 99999 is ahead of the rows around it");
  }
  SECTION("a first row the next one falls behind, with the row after both: the next row is the bad one") {
    const SampleLog log = read_log_text("t,speed,freq\n2,10,50\n1.5,10,50\n6,10,50\n");
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[0].t == Approx(2));
    one_skip(log, "log.csv:3: time goes backwards (1.5 after 2)");
  }
  SECTION("a Carloop run-time cell, amid rows that repeat its second") {
    std::string text = "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED (),\n";
    for (int i = 0; i < 40; ++i)
      text += std::to_string(i == 21 ? 99999 : 10 + i / 2) + ", " + std::to_string(1000 + 10 * i) + ", " +
              std::to_string(20 + i) + ",\n";
    const SampleLog log = read_log_text(text);
    CHECK(log.format == SampleFileFormat::kCarloop);
    CHECK(log.samples.size() == 39);
    CHECK(log.samples.back().t < 40.0);
    one_skip(log, "log.csv:23: time 99999 is ahead of the rows around it");
  }
  SECTION("the first row of a Torque export: the times count from the first row kept") {
    const SampleLog log = read_log_text(
        "Device Time,GPS Speed (Meters/second),Engine RPM(rpm)\n"
        "40:00.5,10,2000\n"
        "20:00.5,10,2000\n"
        "20:01.5,11,2100\n"
        "20:02.5,12,2200\n");
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[0].t == Approx(0));
    CHECK(log.samples[2].t == Approx(2));
    CHECK(log.skipped.size() == 1);
  }
  SECTION("the messages are in line order, a time judged late among bad cells") {
    const SampleLog log = read_log_text("t,speed,freq\n1,1,1\n1e9,1,1\nx,1,1\n2,1,1\n");
    REQUIRE(log.skipped.size() == 2);
    CHECK(log.skipped[0].rfind("log.csv:3: time 1e+09 is ahead", 0) == 0);
    CHECK(log.skipped[1].rfind("log.csv:4: not a number", 0) == 0);
  }
}

TEST_CASE("io: a time beyond any clock is a bad cell, on the last row too, where no row after it shows it") {
  SECTION("generic") {
    const SampleLog log = read_log_text("t,speed,freq\n1,10,50\n2,10,50\n1e308,10,50\n");
    REQUIRE(log.samples.size() == 2);
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:4: time beyond any log's clock in column t", 0) == 0);
  }
  SECTION("Carloop: the fit of its row times saw an overflow and gave a time of minus infinity") {
    const SampleLog log = read_log_text(
        "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED ()\n0,1000,10\n1,1100,11\n7\n1e308,1200,12\n");
    REQUIRE(log.samples.size() == 2);
    for (const auto& s : log.samples)
      CHECK(std::isfinite(s.t));
    CHECK(log.skipped_count == 2);  // the short row and the time
  }
}

TEST_CASE(
    "io: a Torque clock cell out of range or off its neighbours costs its row, not an hour on every row "
    "after it") {
  const auto times = [](const SampleLog& log) {
    std::vector<double> t;
    for (const auto& s : log.samples)
      t.push_back(s.t);
    return t;
  };
  SECTION("a cell no clock shows") {
    const SampleLog log = read_log_text(
        "Device Time,Engine RPM(rpm),Speed (OBD)(km/h)\n"
        "10:00.0,1000,10\n10:01.0,1100,11\n99:02.0,1200,12\n10:03.0,1300,13\n10:04.0,1400,14\n");
    CHECK(times(log) == std::vector<double>{0, 1, 3, 4});
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:4: unreadable time '99:02.0'", 0) == 0);
    CHECK(times(read_log_text(
                    "Device Time,Engine RPM(rpm),Speed (OBD)(km/h)\n10:00.0,1000,10\n10:61.0,1100,11\n"
                    "Thu Jan 11 25:06:38 EST 2018,1200,12\n"))
              .size() == 1);
  }
  SECTION("a cell in range, jumping away and back") {
    const SampleLog log = read_log_text(
        "Device Time,Engine RPM(rpm),Speed (OBD)(km/h)\n"
        "10:00.0,1000,10\n10:01.0,1100,11\n45:00.0,1200,12\n10:03.0,1300,13\n10:04.0,1400,14\n");
    CHECK(times(log) == std::vector<double>{0, 1, 3, 4});
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:4: time jumps 2099 s away from the rows around it", 0) == 0);
  }
  SECTION("a wrap and a pause are kept") {
    const SampleLog log = read_log_text(
        "Device Time,Engine RPM(rpm),Speed (OBD)(km/h)\n"
        "59:58.0,1000,10\n59:59.0,1100,11\n00:00.0,1200,12\n05:00.0,1300,13\n05:01.0,1400,14\n");
    CHECK(times(log) == std::vector<double>{0, 1, 2, 302, 303});
    CHECK(log.skipped.empty());
  }
}

TEST_CASE("io: clock cells with a zone, in ISO 8601 or on a 12-hour clock read as times of day") {
  SECTION("Torque's GPS Time with a GMT offset word, the only time column") {
    const SampleLog log = read_log_text(
        "GPS Time,Engine RPM(rpm),Speed (OBD)(km/h)\n"
        "Wed Feb 23 06:42:46 GMT+08:00 2022,1200,36\n"
        "-,1250,37\n"
        "Wed Feb 23 06:42:48 GMT+08:00 2022,1300,38\n");
    REQUIRE(log.samples.size() == 2);
    CHECK(log.skipped_count == 1);  // the row without a GPS fix has no time
    CHECK(log.samples[1].t == Approx(2));
  }
  SECTION("ISO 8601 date-times, with Z or an offset, across midnight") {
    for (const std::string zone : {"Z", "+08:00", "-05:00", ""}) {
      std::string text = "timestamp,rpm,speed (km/h)\n2022-02-23T23:59:59.5";
      text += zone;
      text += ",1200,36\n2022-02-24T00:00:01.0";
      text += zone;
      text += ",1300,36\n";
      const SampleLog log = read_log_text(text);
      REQUIRE(log.samples.size() == 2);
      CHECK(log.samples[1].t == Approx(1.5));
    }
  }
  SECTION("a 12-hour clock runs on from 12:59 PM to 1:00 PM and from 11:59 PM past midnight") {
    const SampleLog log = read_log_text(
        "Time,Engine RPM,Speed (km/h)\n12:59:59 PM,1200,36\n1:00:01 PM,1300,37\n11:59:59PM,1400,38\n"
        "12:00:01 am,1500,39\n");
    REQUIRE(log.samples.size() == 4);
    CHECK(log.samples[1].t == Approx(2));
    CHECK(log.samples[2].t == Approx(11 * 3600.0));
    CHECK(log.samples[3].t == Approx(11 * 3600.0 + 2));
    CHECK(log.skipped_count == 0);
  }
  SECTION("\"am\" or \"pm\" elsewhere in the cell than right after the time is not a 12-hour clock") {
    // German "am" ("on") before a date and a 24-hour time.
    const SampleLog log = read_log_text(
        "Time,Engine RPM,Speed (km/h)\nam 23.02.2022 14:42:46,1200,36\nam 23.02.2022 14:42:48,1300,37\n");
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].t == Approx(2));
    CHECK(log.skipped_count == 0);
  }
}
