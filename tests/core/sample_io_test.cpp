#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/sample_io.hpp"
#include "tests/core/read_log_text.hpp"
#include "tests/test_util.hpp"

using gearpulse::read_samples;
using gearpulse::Sample;
using gearpulse::SampleFileError;
using gearpulse::SampleFileFormat;
using gearpulse::SampleLog;
using gearpulse::test::error_of;
using gearpulse::test::read_log_text;

namespace {

constexpr double kPiOver100 = 3.14159265358979 / 100.0;

}  // namespace

TEST_CASE("io: generic CSV with empty cells and extra columns") {
  const SampleLog log = read_log_text("t,speed,freq,snr_db\n0,1.5,50,12\n1,,51,\n2,2.5,,3\n");
  CHECK(log.format == SampleFileFormat::kGeneric);
  REQUIRE(log.samples.size() == 3);
  CHECK(log.samples[0].speed == Approx(1.5));
  CHECK(log.samples[0].freq == Approx(50));
  CHECK_FALSE(log.samples[1].has_speed());
  CHECK(log.samples[1].freq == Approx(51));
  CHECK_FALSE(log.samples[2].has_freq());
  CHECK(log.skipped_count == 0);
  // Further columns are ignored whatever their names, even those another format is told by.
  const SampleLog named =
      read_log_text("t,speed,freq,Engine RPM(rpm),ENGINE_RPM (),VEHICLE_SPEED ()\n0,1.5,50,,,\n");
  CHECK(named.format == SampleFileFormat::kGeneric);
  REQUIRE(named.samples.size() == 1);
  CHECK(named.samples[0].freq == Approx(50));
}

TEST_CASE("io: a generic log in km/h or in ms reads, with a warning that says so") {
  // A drive at 1 Hz, 0-90 km/h: in m/s, in km/h, and in m/s with t in ms.
  std::string mps = "t,speed,freq\n", kmh = mps, ms = mps;
  for (int i = 0; i < 100; ++i) {
    const double v = 25.0 * std::sin(kPiOver100 * i) * std::sin(kPiOver100 * i);
    mps += std::to_string(i) + "," + std::to_string(v) + ",40\n";
    kmh += std::to_string(i) + "," + std::to_string(v * 3.6) + ",40\n";
    ms += std::to_string(i * 1000) + "," + std::to_string(v) + ",40\n";
  }
  CHECK(read_log_text(mps).warnings.empty());
  const SampleLog fast = read_log_text(kmh);
  REQUIRE(fast.warnings.size() == 1);
  INFO(fast.warnings[0]);
  CHECK(fast.warnings[0].starts_with("log.csv: speeds up to 90 m/s (324 km/h)"));
  CHECK(fast.warnings[0].find("in km/h?") != std::string::npos);
  const SampleLog slow = read_log_text(ms);
  REQUIRE(slow.warnings.size() == 1);
  CHECK(slow.warnings[0] ==
        "log.csv: rows 1000 s apart at the median: the t,speed,freq format takes seconds; is t in ms?");
}

TEST_CASE("io: bad rows are skipped and reported with file and line") {
  const SampleLog log = read_log_text(
      "t,speed,freq\r\n"
      "2,1,50\r\n"
      "1,nan,50\r\n"
      "2,-3,50\r\n"
      "3,abc,50\r\n"
      "4,1\r\n"
      "1.5,1,50\r\n"
      "\r\n"
      "5,1,inf\r\n"
      "6,2,60\r\n");
  REQUIRE(log.samples.size() == 2);
  CHECK(log.samples[1].t == Approx(6));
  CHECK(log.skipped_count == 6);
  REQUIRE(log.skipped.size() == 6);
  CHECK(log.skipped[0].rfind("log.csv:3: non-finite", 0) == 0);
  CHECK(log.skipped[1].rfind("log.csv:4: negative", 0) == 0);
  CHECK(log.skipped[2].rfind("log.csv:5: not a number", 0) == 0);
  CHECK(log.skipped[3].rfind("log.csv:6: too few cells", 0) == 0);
  CHECK(log.skipped[4].rfind("log.csv:7: time goes backwards", 0) == 0);
  CHECK(log.skipped[5].rfind("log.csv:9: non-finite", 0) == 0);
}

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

TEST_CASE("io: empty, headerless and useless files are one-line errors") {
  CHECK(error_of("") == "log.csv: empty file");
  CHECK(error_of("\n\n") == "log.csv: empty file");
  CHECK(error_of("1,2,3\n4,5,6\n").rfind("log.csv:1: unrecognised header", 0) == 0);
  CHECK(error_of("t,speed,freq\n").find("no data rows") != std::string::npos);
  CHECK(error_of("t,speed,freq\n0,x,1\n").find("log.csv:2: not a number") != std::string::npos);
  CHECK(error_of("t,speed,freq\n0,,\n1,,\n").find("no usable samples") != std::string::npos);
  CHECK(error_of("# only a comment\n") == "log.csv: empty file");
  CHECK(error_of(std::string("\xFF\xFEt\0,\0", 6)) ==
        "log.csv:1: UTF-16 text: save the log as UTF-8 or ASCII text");
  for (const std::string& e : {error_of(""), error_of("t,speed,freq\n0,x,1\n")})
    CHECK(e.find('\n') == std::string::npos);
}

TEST_CASE("io: comment lines and a spreadsheet's sep= line before the header are passed over") {
  const SampleLog log = read_log_text("# logger 1.2\n\n# car: test\nt,speed,freq\n0,1,20\n1,2,21\n");
  REQUIRE(log.samples.size() == 2);
  CHECK(log.skipped_count == 0);
  const SampleLog sep = read_log_text("sep=;\r\nTime;Engine RPM;Speed (km/h)\r\n0;600;0\r\n0,5;1200;18\r\n");
  CHECK(sep.format == SampleFileFormat::kColumns);
  REQUIRE(sep.samples.size() == 2);
  CHECK(sep.samples[1].t == Approx(0.5));
  CHECK(sep.samples[1].speed == Approx(5));
  const SampleLog numbered = read_log_text("#,Time,Engine RPM,Speed (km/h)\n1,0,600,0\n2,1,1200,18\n");
  CHECK(numbered.format == SampleFileFormat::kColumns);
  REQUIRE(numbered.samples.size() == 2);
  CHECK(numbered.samples[1].speed == Approx(5));
  const SampleLog tab = read_log_text("sep=\t\nt\tspeed\tfreq\n0\t1,5\t20\n");
  REQUIRE(tab.samples.size() == 1);
  CHECK(tab.samples[0].speed == Approx(1.5));
}

TEST_CASE("io: a sep= line with spaces after it states the delimiter") {
  const SampleLog spaced = read_log_text("sep=; \nt;speed;freq\n0;1,5;20\n");
  REQUIRE(spaced.samples.size() == 1);
  CHECK(spaced.samples[0].speed == Approx(1.5));
  const SampleLog tab = read_log_text("sep=\t \nt\tspeed\tfreq\n0\t1,5\t20\n");
  REQUIRE(tab.samples.size() == 1);
  CHECK(tab.samples[0].speed == Approx(1.5));
}

TEST_CASE("io: under a sep= line, '#' and the delimiter it states start a header, not a comment") {
  // Only the stated delimiter makes "#" a column's name: "#|..." under "sep=|", not "#;..." under it.
  const SampleLog piped = read_log_text("sep=|\n#|Time|Engine RPM|Speed (km/h)\n1|0|600|0\n2|1|1200|18\n");
  CHECK(piped.format == SampleFileFormat::kColumns);
  REQUIRE(piped.samples.size() == 2);
  CHECK(piped.samples[1].speed == Approx(5));
  const SampleLog commented = read_log_text("sep=|\n#;note\nt|speed|freq\n0|1|20\n");
  CHECK(commented.format == SampleFileFormat::kGeneric);
  CHECK(commented.samples.size() == 1);
}

TEST_CASE("io: lines ended by a CR alone read as lines, numbered as such") {
  const SampleLog log =
      read_log_text("Time (s),Engine RPM,Speed (mph)\r0,600,0\r1,1200,10\rx,1,1\r2,1300,11\r");
  CHECK(log.format == SampleFileFormat::kColumns);
  REQUIRE(log.samples.size() == 3);
  CHECK(log.samples[2].t == Approx(2));
  CHECK(log.samples[2].speed == Approx(11 * 0.44704));
  REQUIRE(log.skipped.size() == 1);
  CHECK(log.skipped[0].rfind("log.csv:4: not a number", 0) == 0);
  CHECK(read_log_text("t,speed,freq\r\n0,1,20\r\r\n1,2,21\n").samples.size() == 2);
}

TEST_CASE("io: a header of thousands of columns is an error, a row of millions of commas only its columns") {
  CHECK(error_of("t,speed,freq" + std::string(5000, ',') + "\n0,1,2\n") ==
        "log.csv:1: header has more than 4096 columns");
  // The row's cells past the header's columns are ignored unsplit: the row reads as any other.
  const SampleLog log =
      read_log_text("t,speed,freq,note\n0,1,2\n1,3,4" + std::string(5'000'000, ',') + "\n2,5,6\n");
  REQUIRE(log.samples.size() == 3);
  CHECK(log.samples[1].speed == 3.0);
  CHECK(log.samples[1].freq == 4.0);
  CHECK(log.skipped_count == 0);
}

TEST_CASE("io: the skip list is capped but every skip is counted") {
  std::string text = "t,speed,freq\n";
  for (int i = 0; i < 50; ++i)
    text += "x,1,2\n";
  text += "1,1,1\n";
  gearpulse::ReadOptions options;
  options.max_messages = 5;
  const SampleLog log = read_log_text(text, options);
  CHECK(log.skipped_count == 50);
  CHECK(log.skipped.size() == 5);
  CHECK(log.samples.size() == 1);
}

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

TEST_CASE("io: cells at the edges of what a log holds") {
  SECTION("a quoted empty cell is missing, not a bad row") {
    const SampleLog log = read_log_text("t,speed,freq\n0,\"\",50\n1,\" \",51\n");
    REQUIRE(log.samples.size() == 2);
    CHECK_FALSE(log.samples[0].has_speed());
    CHECK_FALSE(log.samples[1].has_speed());
    CHECK(log.skipped_count == 0);
  }
  SECTION("a negative time is a time (a logger's clock set before the start), a time past any clock not") {
    const SampleLog log = read_log_text("t,speed,freq\n-2,1,50\n-1,1,50\n-1e300,1,50\n0,1,50\n");
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[0].t == Approx(-2));
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:4: time beyond any log's clock", 0) == 0);
  }
  SECTION("a frequency of 0 is an engine at rest; one above 0 but below any engine's is a bad cell") {
    const SampleLog log = read_log_text("t,speed,freq\n0,0,0\n1,0,0.0005\n2,0,0.002\n");
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[0].freq == 0.0);
    CHECK(log.samples[1].freq == Approx(0.002));
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:3: frequency 0.0005 Hz is outside any engine's", 0) == 0);
  }
  SECTION("Torque's N/A is a missing value; a clock's 60 seconds is no clock") {
    const SampleLog log = read_log_text(
        "Device Time,Engine RPM(rpm),Speed (OBD)(km/h)\n"
        "10:00.0,1000,N/A\n10:01.0,1100,11\n10:60.0,1200,12\n");
    REQUIRE(log.samples.size() == 2);
    CHECK_FALSE(log.samples[0].has_speed());
    CHECK(log.samples[0].freq == Approx(1000.0 / 60.0));
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:4: unreadable time '10:60.0'", 0) == 0);
  }
  SECTION("rows in milliseconds are told from ten steps on, not fewer") {
    const auto rows = [](int n) {
      std::string text = "t,speed,freq\n";
      for (int i = 0; i < n; ++i)
        text += std::to_string(i * 1000) + ",10,40\n";
      return text;
    };
    CHECK(read_log_text(rows(11)).warnings.size() == 1);
    CHECK(read_log_text(rows(10)).warnings.empty());
  }
}

namespace {

// Serves `text`, then fails as a disk does mid-file (the stream sets badbit on the exception).
class FailingBuf : public std::streambuf {
 public:
  explicit FailingBuf(std::string text) : text_(std::move(text)) {
    setg(text_.data(), text_.data(), text_.data() + text_.size());
  }

 protected:
  int_type underflow() override { throw std::ios_base::failure("I/O error"); }

 private:
  std::string text_;
};

}  // namespace

TEST_CASE("io: a read error mid-file is an error and no log cut short") {
  FailingBuf buf("t,speed,freq\n0,1,50\n1,1,50\n2,1,");
  std::istream in(&buf);
  try {
    (void)read_samples(in, "log.csv");
    FAIL("a log cut short by a read error was returned");
  } catch (const SampleFileError& e) {
    CHECK(std::string(e.what()) == "log.csv: read error");
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
          "log.csv:1: speed column 'Speed' states no unit: name it with km/h, mph, m/s or knots");
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

TEST_CASE("io: a log saved with semicolons reads its decimal commas") {
  const SampleLog log = read_log_text("\"t\";\"speed\";\"freq\"\n0;1,5;20,25\n1;2;21\n");
  CHECK(log.format == SampleFileFormat::kGeneric);
  REQUIRE(log.samples.size() == 2);
  CHECK(log.samples[0].speed == Approx(1.5));
  CHECK(log.samples[0].freq == Approx(20.25));
  const SampleLog tabs = read_log_text("Time\tEngine RPM\tSpeed (km/h)\n0\t600\t0\n1\t1200\t18\n");
  CHECK(tabs.format == SampleFileFormat::kColumns);
  REQUIRE(tabs.samples.size() == 2);
  CHECK(tabs.samples[1].speed == Approx(5));
}

TEST_CASE("io: a quoted cell keeps the delimiter inside it, in the header and in the data") {
  const SampleLog commas = read_log_text(
      "\"Time (s)\",\"Engine speed, rpm\",\"Vehicle speed, km/h\",\"Note\"\n"
      "0,600,0,\"idle, \"\"warm\"\"\"\n1,1200,18,\"a, b\"\n");
  CHECK(commas.format == SampleFileFormat::kColumns);
  CHECK(commas.speed_column == "Vehicle speed, km/h");
  CHECK(commas.skipped_count == 0);
  REQUIRE(commas.samples.size() == 2);
  CHECK(commas.samples[1].speed == Approx(5));
  CHECK(commas.samples[1].freq == Approx(20));
  // Commas inside a quoted name do not make the header comma-separated.
  const SampleLog semicolons =
      read_log_text("\"Time\";\"Engine RPM, rpm\";\"Speed, km/h\"\n0;600;0\n\"1,5\";1200;\"18,0\"\n");
  CHECK(semicolons.format == SampleFileFormat::kColumns);
  REQUIRE(semicolons.samples.size() == 2);
  CHECK(semicolons.samples[1].t == Approx(1.5));
  CHECK(semicolons.samples[1].speed == Approx(5));
  const SampleLog stray_name =
      read_log_text("Wheel (17\");Time;Engine RPM;Speed (km/h)\n1;0;600;0\n1;1;1200;18\n");
  REQUIRE(stray_name.samples.size() == 2);
  CHECK(stray_name.samples[1].speed == Approx(5));
  // A quote that never closes is a character like any other: the cells split as before.
  const SampleLog stray = read_log_text("t,speed,freq,note\n0,1,20,5\" screen\n1,2,21,x\n");
  REQUIRE(stray.samples.size() == 2);
  CHECK(stray.samples[0].freq == Approx(20));
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

TEST_CASE("io: written CSV reads back") {
  const std::vector<Sample> in = {
      {0.0, 1.25, 40.5}, {0.5, gearpulse::kMissing, 41.0}, {1.0, 3.0, gearpulse::kMissing}};
  std::stringstream buf;
  gearpulse::write_samples(buf, in);
  const SampleLog log = read_samples(buf, "mem");
  REQUIRE(log.samples.size() == 3);
  CHECK(log.samples[0].speed == 1.25);
  CHECK_FALSE(log.samples[1].has_speed());
  CHECK_FALSE(log.samples[2].has_freq());
}

TEST_CASE("io: every real log reads with sensible values and no unit warning") {
  const std::filesystem::path real = gearpulse::test::real_data_dir();
  if (!std::filesystem::exists(real)) GEARPULSE_SKIP_TEST("no real logs at " << real);
  std::size_t files = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(real)) {
    if (entry.path().extension() != ".csv") continue;
    ++files;
    std::ifstream in(entry.path(), std::ios::binary);
    const SampleLog log = read_samples(in, entry.path().string());
    INFO(entry.path().string());
    CHECK(log.warnings.empty());  // no log of a known format reads as km/h or milliseconds
    CHECK(log.samples.size() > 100);
    CHECK(log.skipped_count * 50 <= log.samples.size() + log.skipped_count);
    std::size_t moving = 0;
    for (const Sample& s : log.samples) {
      if (s.has_speed()) CHECK(s.speed < 70.0);
      if (s.has_freq()) CHECK(s.freq < 150.0);
      if (s.has_speed() && s.has_freq() && s.speed > 2.0) ++moving;
    }
    CHECK(moving > 50);
    CHECK(std::is_sorted(log.samples.begin(), log.samples.end(),
                         [](const Sample& a, const Sample& b) { return a.t < b.t; }));
  }
  CHECK(files >= 28);
}

TEST_CASE("io: mangled logs of every format give samples or a one-line error, nothing else") {
  // The head of each real log, generic CSV beside them, then each mangled at random: bytes replaced,
  // dropped or inserted (commas, quotes, digits, signs, NaN and infinity spelled out, NUL), lines
  // repeated, cut or swapped. Whatever comes out is either samples with sane values in time order or a
  // SampleFileError naming the file on one line: no other exception, no crash (the sanitizer builds run
  // this too).
  // The real logs' heads, when the logs are here (the test of them above skips otherwise).
  const std::filesystem::path real = gearpulse::test::real_data_dir();
  std::vector<std::string> heads;
  if (std::filesystem::exists(real)) {
    for (const auto& entry : std::filesystem::recursive_directory_iterator(real)) {
      const std::string name = entry.path().filename().string();
      if (entry.path().extension() != ".csv" || (name != "drive1.csv" && name.rfind("drive", 0) == 0) ||
          name.rfind("long", 0) == 0)
        continue;
      std::ifstream in(entry.path(), std::ios::binary);
      std::string head, line;
      for (int i = 0; i < 60 && std::getline(in, line); ++i)
        head += line + "\n";
      heads.push_back(head);
    }
  }
  heads.push_back("t,speed,freq\n0,0,12.5\n1,1.5,20\n2,3.1,31.2\n3,,40\n4,5.5,\n5,7.2,44.1\n");
  const std::vector<std::string> pieces = {
      ",",   "\"",  "\n",   "-",     "+",  "e",    "9", ".",
      "nan", "inf", "-inf", "1e308", "  ", "#N/A", "-", std::string(1, '\0'),
      "\r"};
  std::mt19937 rng(23);
  std::size_t read = 0, refused = 0;
  for (const std::string& head : heads) {
    for (int trial = 0; trial < 150; ++trial) {
      const std::string text = gearpulse::test::mangle(head, 1 + static_cast<int>(rng() % 12), pieces, rng);
      INFO("input:\n" << text);
      try {
        const SampleLog log = read_log_text(text);
        ++read;
        for (const Sample& s : log.samples) {
          REQUIRE(std::isfinite(s.t));
          if (s.has_speed()) REQUIRE(s.speed >= 0.0);
          if (s.has_freq()) REQUIRE(s.freq >= 0.0);
        }
        REQUIRE(std::is_sorted(log.samples.begin(), log.samples.end(),
                               [](const Sample& a, const Sample& b) { return a.t < b.t; }));
      } catch (const SampleFileError& e) {
        ++refused;
        const std::string what = e.what();
        REQUIRE(what.rfind("log.csv", 0) == 0);
        REQUIRE(what.find('\n') == std::string::npos);
      }
    }
  }
  INFO("read " << read << ", refused " << refused);
  CHECK(read > 0);
  CHECK(refused > 0);
}
