// The log readers on what other people's exports hold: quoted cells over several lines, speeds in knots,
// cells that spell "no value", and what loggers and spreadsheets write around the data (byte-order marks,
// trailing delimiters, a header repeated after a restart, long lines). tests/core/sample_io_test.cpp,
// log_formats_test.cpp and log_times_test.cpp hold the formats themselves.
#include <catch2/catch.hpp>

#include <sstream>
#include <string>
#include <vector>

#include "core/sample_io.hpp"
#include "tests/core/read_log_text.hpp"

using gearpulse::read_samples;
using gearpulse::SampleFileError;
using gearpulse::SampleFileFormat;
using gearpulse::SampleLog;
using gearpulse::test::error_of;
using gearpulse::test::read_log_text;

namespace {

constexpr double kKnot = 1852.0 / 3600.0;  // m/s: a nautical mile (1852 m) an hour

}  // namespace

TEST_CASE("io: a quoted cell holding line breaks is one cell, its row numbered by its first line") {
  SECTION("a note over two and three lines in a generic log") {
    const SampleLog log = read_log_text(
        "t,speed,freq,note\n"
        "0,1,20,\"stopped at the lights,\nthen off\"\n"
        "1,2,21,\"a \"\"quoted\"\" word\non\nthree lines\"\n"
        "2,x,22,\n"
        "3,4,23,plain\n");
    REQUIRE(log.samples.size() == 3);
    CHECK(log.samples[1].t == 1.0);
    CHECK(log.samples[1].speed == 2.0);
    CHECK(log.samples[2].t == 3.0);
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:7: not a number in column speed", 0) == 0);
  }
  SECTION("column names broken over lines, as a spreadsheet wraps them") {
    const SampleLog log = read_log_text(
        "\"Time\n(s)\",\"Engine\nRPM\",\"Vehicle speed\r\n(km/h)\"\r\n"
        "0,600,0\r\n1,1200,18\r\nx,1,1\r\n");
    CHECK(log.format == SampleFileFormat::kColumns);
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].speed == Approx(5));
    CHECK(log.samples[1].freq == Approx(20));
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:7: not a number", 0) == 0);
  }
  SECTION("in a semicolon log with decimal commas and in one whose lines end in a CR alone") {
    const SampleLog semi =
        read_log_text("Time;Engine RPM;Speed (km/h);Note\n0;600;0;\"a; b\nc\"\n0,5;1200;18;\n");
    REQUIRE(semi.samples.size() == 2);
    CHECK(semi.samples[1].t == Approx(0.5));
    const SampleLog cr = read_log_text("t,speed,freq,note\r0,1,20,\"x\ry\"\r1,2,21,\rz,1,1\r");
    REQUIRE(cr.samples.size() == 2);
    REQUIRE(cr.skipped.size() == 1);
    CHECK(cr.skipped[0].rfind("log.csv:5: not a number", 0) == 0);
  }
  SECTION("a quote in a cell's text, not at its start, opens nothing") {
    const SampleLog log = read_log_text("t,speed,freq,note\n0,1,20,17\" wheels\n1,2,21,x\n2,3,22,y\"\n");
    CHECK(log.samples.size() == 3);
    CHECK(log.skipped_count == 0);
  }
}

TEST_CASE("io: a quote opened at a cell's start that does not close as a cell does is a character") {
  SECTION("never closed: each line is a row of its own, as without quotes") {
    const SampleLog log = read_log_text("t,speed,freq,note\n0,1,20,\"screen\n1,2,21,x\n2,3,22,y\n");
    CHECK(log.samples.size() == 3);
    CHECK(log.skipped_count == 0);
  }
  SECTION("a later quote with text after it is no closing quote: no rows are joined") {
    const SampleLog log = read_log_text("t,speed,freq,note\n0,1,20,\"a\n1,2,21,x\"y\n2,3,22,z\n");
    CHECK(log.samples.size() == 3);
    CHECK(log.skipped_count == 0);
  }
  SECTION("a line inside it with a row's delimiters is a row: the quote was a character") {
    const SampleLog log = read_log_text("t,speed,freq,note\n0,1,20,\"a\n1,2,21,x\n2,3,22,y\"\n3,4,23,z\n");
    CHECK(log.samples.size() == 4);
    CHECK(log.skipped_count == 0);
  }
  SECTION("a cell longer than any note: its lines are rows, each bad one reported, none joined silently") {
    std::string text = "t,speed,freq,note\n0,1,20,\"start\n";
    for (int i = 0; i < 40; ++i)
      text += "more text\n";
    text += "end\"\n1,2,21,x\n";
    const SampleLog log = read_log_text(text);
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].t == 1.0);
    CHECK(log.skipped_count == 41);
    REQUIRE_FALSE(log.skipped.empty());
    CHECK(log.skipped[0].rfind("log.csv:3: too few cells", 0) == 0);
  }
}

TEST_CASE("io: a speed in knots is converted, from a column's name or a PID's unit") {
  for (const std::string name :
       {"Speed (knots)", "GPS speed [kn]", "speed kt", "Speed (kts)", "speed_knots", "Speed (knot)"}) {
    INFO(name);
    const SampleLog log = read_log_text("time,rpm," + name + "\n0,800,10\n1,900,20\n");
    CHECK(log.format == SampleFileFormat::kColumns);
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].speed == Approx(20 * kKnot));
  }
  // Words that hold the letters are no unit: the column states none.
  CHECK(error_of("time,rpm,Speed knock\n0,800,10\n").find("states no unit") != std::string::npos);
  const SampleLog pid = read_log_text(
      "SECONDS;PID;VALUE;UNITS\n0;Speed (GPS);10;kn\n1;Engine RPM;800;rpm\n2;Speed (GPS);20;knots\n");
  REQUIRE(pid.samples.size() == 1);
  CHECK(pid.samples[0].speed == Approx(15 * kKnot));
}

TEST_CASE("io: a row of units under the header names the units its columns' names do not") {
  const SampleLog log =
      read_log_text("Time,Engine speed,Vehicle speed,Throttle\ns,rpm,kn,%\n0,800,0,5\n1,900,20,6\n");
  CHECK(log.format == SampleFileFormat::kColumns);
  CHECK(log.speed_column == "Vehicle speed");  // the name written, its unit stated in its units row
  CHECK(log.speed_unit == "knots");
  CHECK(log.speed_unit_stated_in == "its units row");
  REQUIRE(log.samples.size() == 2);
  CHECK(log.samples[1].t == 1.0);
  CHECK(log.samples[1].speed == Approx(20 * kKnot));
  CHECK(log.samples[1].freq == Approx(15));
  CHECK(log.skipped_count == 0);
  const SampleLog ms = read_log_text("Time,Engine RPM,GPS speed\n\nms,,km/h\n0,800,0\n500,900,18\n");
  REQUIRE(ms.samples.size() == 2);
  CHECK(ms.samples[1].t == Approx(0.5));
  // A first data row is no units row: the speed states no unit, as without one.
  CHECK(error_of("Time,Engine RPM,Vehicle speed\n0,800,-\n") ==
        "log.csv:1: speed column 'Vehicle speed' states no unit: name it with km/h, mph, m/s or knots, or "
        "pass --speed-unit");
  CHECK(error_of("Time,Mode,Note\ns,-,text\n").rfind("log.csv:1: unrecognised header 'Time,Mode,Note'", 0) ==
        0);
  // A Freematics logger's `ms:PID=value` lines (after its `#FREEMATICS...` comment line) are named, with the
  // way to a table.
  const std::string freematics = error_of("#FREEMATICSEV=1,TS=39890\n40620:0=40620 \n40620:10D=12 \n");
  CHECK(freematics.rfind("log.csv:2: unrecognised header '40620:0=40620 ': a Freematics log", 0) == 0);
  CHECK(freematics.find("10C (rpm) and 10D (speed, km/h)") != std::string::npos);
  CHECK(error_of("12:30,x\n").find("Freematics") == std::string::npos);
}

TEST_CASE("io: lines of an app's notes before the header are passed over, up to 32") {
  const std::string notes =
      "This file is created using a lap timer v7.4\nFormat,3\nSession title,\"Evening, dry\"\n"
      "Created,15/03/2023,13:26\n\n";
  const SampleLog log = read_log_text(notes + "Time (s);Engine RPM;Speed (km/h)\n0;800;0\n1;900;18\nx;1;1\n");
  CHECK(log.format == SampleFileFormat::kColumns);
  REQUIRE(log.samples.size() == 2);
  CHECK(log.samples[1].speed == Approx(5));
  REQUIRE(log.skipped.size() == 1);
  CHECK(log.skipped[0].rfind("log.csv:9: not a number", 0) == 0);
  // Without a header after them, or past 32 lines, the first line is the unrecognised header.
  CHECK(error_of(notes).rfind("log.csv:1: unrecognised header 'This file is created", 0) == 0);
  std::string many;
  for (int i = 0; i < 32; ++i)
    many += "Note," + std::to_string(i) + "\n";
  CHECK(error_of(many + "t,speed,freq\n0,1,20\n").rfind("log.csv:1: unrecognised header 'Note,0'", 0) == 0);
  CHECK(read_log_text(many.substr(many.find('\n') + 1) + "t,speed,freq\n0,1,20\n").samples.size() == 1);
}

TEST_CASE("io: a cell that spells no value is missing in every format, NaN a bad cell") {
  SECTION("generic: -, NA, N/A, null and spreadsheet errors are empty cells; the row is kept") {
    const SampleLog log =
        read_log_text("t,speed,freq\n0,-,50\n1,NA,51\n2,n/a,52\n3,null,53\n4,#N/A,54\n5,3,#DIV/0!\n6,4,-\n");
    REQUIRE(log.samples.size() == 7);
    CHECK(log.skipped_count == 0);
    for (int i = 0; i < 5; ++i) {
      CHECK_FALSE(log.samples[i].has_speed());
      CHECK(log.samples[i].freq == 50.0 + i);
    }
    CHECK_FALSE(log.samples[5].has_freq());
    CHECK_FALSE(log.samples[6].has_freq());
  }
  SECTION("NaN is a number no computation should give: the row is bad, and the message says so") {
    const SampleLog log = read_log_text("t,speed,freq\n0,1,50\n1,NaN,51\n2,1,nan\n3,1,52\n");
    REQUIRE(log.samples.size() == 2);
    REQUIRE(log.skipped.size() == 2);
    CHECK(log.skipped[0].rfind("log.csv:3: non-finite value in column speed: 'NaN'", 0) == 0);
    CHECK(log.skipped[0].find("an empty cell is a missing value") != std::string::npos);
    CHECK(log.skipped[1].rfind("log.csv:4: non-finite value in column freq", 0) == 0);
  }
  SECTION("a missing time is a bad row, whatever spells it") {
    const SampleLog log = read_log_text("t,speed,freq\n0,1,50\n-,1,50\nN/A,1,50\n3,1,50\n");
    REQUIRE(log.samples.size() == 2);
    REQUIRE(log.skipped.size() == 2);
    CHECK(log.skipped[0] == "log.csv:3: missing t");
    CHECK(log.skipped[1] == "log.csv:4: missing t");
  }
  SECTION("named columns: a speed or rpm that spells no value is missing, as an empty one is") {
    const SampleLog log = read_log_text(
        "time,Engine RPM,Speed (km/h)\n0,800,-\n1,-,36\n2,N/A,\n3,,N/A\n4,1000,#N/A\n5,1100,40\n");
    REQUIRE(log.samples.size() == 5);  // rows 2 and 3 both carry nothing: the second repeats the first
    CHECK(log.skipped_count == 0);
    CHECK_FALSE(log.samples[0].has_speed());
    CHECK_FALSE(log.samples[1].has_freq());
    CHECK(log.samples[1].speed == Approx(10));
    CHECK_FALSE(log.samples[3].has_speed());
  }
  SECTION("a PID reading of no value is a PID the car did not answer") {
    const SampleLog log = read_log_text(
        "SECONDS;PID;VALUE;UNITS\n0;Vehicle speed;36;km/h\n1;Engine RPM;-;rpm\n2;Engine RPM;800;rpm\n"
        "3;Vehicle speed;36;km/h\n");
    REQUIRE(log.samples.size() == 1);
    CHECK(log.skipped_count == 0);
  }
}

TEST_CASE("io: what exports write around the data") {
  SECTION("a Torque Pro export, its header repeated where logging resumed") {
    const std::string header =
        "GPS Time, Device Time, Longitude, Latitude,GPS Speed (Meters/second), Horizontal Dilution of "
        "Precision, Altitude, Bearing, G(x), G(y), G(z), G(calibrated),Engine RPM(rpm),Speed (OBD)(km/h)\n";
    const SampleLog log = read_log_text(header +
                                        "Thu Jan 11 19:06:38 EST 2018,11-Jan-2018 19:06:38.112,-85.7,38.2,10,"
                                        "4.0,150,90,0.1,0.2,9.8,0.0,2000,36\n" +
                                        header +
                                        "Thu Jan 11 19:06:40 EST 2018,11-Jan-2018 19:06:40.112,-85.7,38.2,11,"
                                        "4.0,150,90,0.1,0.2,9.8,0.0,2100,40\n");
    CHECK(log.format == SampleFileFormat::kTorque);
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].t == Approx(2));
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0] == "log.csv:3: the header again (a logger restarted?)");
  }
  SECTION("a header repeated with a byte-order mark, as two files joined end to end") {
    const SampleLog log =
        read_log_text("\xEF\xBB\xBFt,speed,freq\n0,1,20\n1,2,21\n\xEF\xBB\xBFt,speed,freq\n2,3,22\n");
    REQUIRE(log.samples.size() == 3);
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0] == "log.csv:4: the header again (a logger restarted?)");
  }
  SECTION("a header again with columns added after the ones read: its rows read as before") {
    const SampleLog log = read_log_text(
        "Time,Engine RPM,Speed (km/h)\n0,800,10\nTime,Engine RPM,Speed (km/h),Throttle (%)\n1,900,20,15\n");
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].speed == Approx(20 / 3.6));
    CHECK(log.skipped_count == 1);
  }
  SECTION("a column named as Torque names its rpm, in another app's log: read by its names") {
    const SampleLog log = read_log_text("Time,Engine RPM (rpm),Speed (knots)\n0,800,10\n");
    CHECK(log.format == SampleFileFormat::kColumns);
    REQUIRE(log.samples.size() == 1);
    CHECK(log.samples[0].speed == Approx(10 * kKnot));
    CHECK(error_of("Device Time,Engine RPM(rpm)\n10:00.0,800\n") ==
          "log.csv:1: no speed values (no OBD speed column and no GPS speed value)");
  }
  SECTION("a value written with a plus sign; a file saved with two byte-order marks") {
    const SampleLog log = read_log_text("\xEF\xBB\xBF\xEF\xBB\xBFt,speed,freq\n+0,+1.5,+20\n1,+-2,21\n");
    REQUIRE(log.samples.size() == 1);
    CHECK(log.samples[0].speed == 1.5);
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:3: not a number in column speed: '+-2'", 0) == 0);
  }
  SECTION("a number beyond a double's range is said as one, not as no number") {
    const SampleLog log = read_log_text("t,speed,freq\n0,1e400,20\n1,2,1e-400\n2,3,22\n");
    REQUIRE(log.samples.size() == 1);
    REQUIRE(log.skipped.size() == 2);
    CHECK(log.skipped[0] == "log.csv:2: a number beyond what a double holds in column speed: '1e400'");
    CHECK(log.skipped[1] == "log.csv:3: a number beyond what a double holds in column freq: '1e-400'");
  }
  SECTION("a header with its columns elsewhere is an error at its line: its rows would be misread") {
    CHECK(error_of("Time,Engine RPM,Speed (km/h)\n0,800,10\nTime,Speed (km/h),Engine RPM\n1,20,900\n") ==
          "log.csv:3: a header with other columns (a logger restarted?): the rows after it would be "
          "misread; split the log at this line");
  }
  SECTION("trailing delimiters, a byte-order mark and quoted names, decimal commas") {
    const SampleLog log = read_log_text(
        "\xEF\xBB\xBF\"time\";\"Engine RPM (rpm)\";\"Vehicle speed (km/h)\";\n"
        "\"0,0\";\"800\";\"0\";\n\"0,5\";\"1200\";\"18\";;;\n");
    CHECK(log.format == SampleFileFormat::kColumns);
    REQUIRE(log.samples.size() == 2);
    CHECK(log.samples[1].t == Approx(0.5));
    CHECK(log.samples[1].speed == Approx(5));
    const SampleLog sep = read_log_text(
        "\xEF\xBB\xBFsep=,\nTime (sec),Engine RPM (RPM),Vehicle speed (MPH),\n"
        "0.00,800,0,\n1.00,1200,10,\n");
    REQUIRE(sep.samples.size() == 2);
    CHECK(sep.samples[1].speed == Approx(10 * 0.44704));
  }
  SECTION("a note of a megabyte on one line, and one quoted over lines of 64 KiB") {
    const std::string long_note(1 << 20, 'x');
    std::string quoted_note = "\"";
    for (int i = 0; i < 8; ++i)
      quoted_note.append(1 << 16, 'y').push_back('\n');
    quoted_note += "\"";
    const SampleLog log = read_log_text("t,speed,freq,note\n0,1,20," + long_note + "\n1,2,21," + quoted_note +
                                        "\n2,3,22,\nx,1,1\n");
    REQUIRE(log.samples.size() == 3);
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0].rfind("log.csv:13: not a number", 0) == 0);
  }
}

TEST_CASE("io: a header repeated where the time starts again begins a new drive, the pause put between") {
  using gearpulse::kRestartGap;
  // The samples of two halves read as files of their own, the second's times put on as a restart puts them.
  const auto halves = [](const std::string& first, const std::string& second) {
    SampleLog a = read_log_text(first);
    const SampleLog b = read_log_text(second);
    const double on = a.samples.back().t + kRestartGap - b.samples.front().t;
    for (gearpulse::Sample s : b.samples) {
      s.t += on;
      a.samples.push_back(s);
    }
    return a.samples;
  };
  const auto same = [](const std::vector<gearpulse::Sample>& a, const std::vector<gearpulse::Sample>& b) {
    REQUIRE(a.size() == b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      CHECK(a[i].t == Approx(b[i].t));
      CHECK(a[i].speed == Approx(b[i].speed));
      CHECK(a[i].freq == Approx(b[i].freq));
    }
  };
  SECTION("a generic log whose time starts again from 0, and one whose time jumps back") {
    const std::string first = "t,speed,freq\n0,1,20\n1,2,21\n2,3,22\n";
    const std::string second = "t,speed,freq\n0,4,23\n1,5,24\n";
    const SampleLog log = read_log_text(first + second);
    same(log.samples, halves(first, second));
    CHECK(log.samples[3].t == 2 + kRestartGap);
    CHECK(log.restarts == 1);
    REQUIRE(log.skipped.size() == 1);
    CHECK(log.skipped[0] == "log.csv:5: the header again (a logger restarted?)");
    const SampleLog back = read_log_text(
        "t,speed,freq\n100,1,20\n101,2,21\nt,speed,freq\n50,3,22\n51,4,23\n" + second + "2,6,25\n");
    REQUIRE(back.samples.size() == 7);
    CHECK(back.samples[2].t == 101 + kRestartGap);
    CHECK(back.samples[3].t == 102 + kRestartGap);
    CHECK(back.samples[4].t == 102 + 2 * kRestartGap);
    CHECK(back.samples[6].t == 104 + 2 * kRestartGap);
    CHECK(back.restarts == 2);
    CHECK(back.skipped_count == 2);
  }
  SECTION("named columns, a Carloop log's engine run time and PID rows") {
    same(read_log_text("Time,Engine RPM,Speed (km/h)\n0,800,10\n1,900,20\n"
                       "Time,Engine RPM,Speed (km/h)\n0,1000,30\n1,1100,40\n")
             .samples,
         halves("Time,Engine RPM,Speed (km/h)\n0,800,10\n1,900,20\n",
                "Time,Engine RPM,Speed (km/h)\n0,1000,30\n1,1100,40\n"));
    const std::string carloop = "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED (),\n";
    const SampleLog run =
        read_log_text(carloop + "7,800,10,\n8,900,20,\n" + carloop + "1,1000,30,\n2,1100,40,\n");
    CHECK(run.restarts == 1);
    REQUIRE(run.samples.size() == 4);
    CHECK(run.samples[2].t >= run.samples[1].t + kRestartGap - 3.0);  // a run-time counter is up to 3 s old
    const std::string pid = "SECONDS;PID;VALUE;UNITS\n";
    const SampleLog pids = read_log_text(pid + "5;Engine RPM;800;rpm\n5;Speed;10;km/h\n" + pid +
                                         "1;Engine RPM;900;rpm\n1;Speed;20;km/h\n");
    CHECK(pids.restarts == 1);
    REQUIRE(pids.samples.size() == 2);
    CHECK(pids.samples[1].t == Approx(pids.samples[0].t + kRestartGap));
    CHECK(pids.samples[1].speed == Approx(20 / 3.6));
  }
  SECTION("a header repeated where the time goes on") {
    const SampleLog on = read_log_text("t,speed,freq\n0,1,20\n1,2,21\nt,speed,freq\n2,3,22\n");
    CHECK(on.restarts == 0);
    REQUIRE(on.samples.size() == 3);
    CHECK(on.samples[2].t == 2);
  }
}

TEST_CASE("io: a time falling back over 5 s without a header begins a new drive, rows out of order do not") {
  using gearpulse::kRestartGap;
  // The file's samples equal those of its halves read as files of their own, the second's times put on.
  const auto same_as_halves = [](const std::string& header, const std::string& first,
                                 const std::string& second, std::size_t restarts = 1) {
    const SampleLog log = read_log_text(header + first + second);
    SampleLog a = read_log_text(header + first);
    const SampleLog b = read_log_text(header + second);
    CHECK(log.restarts == restarts);
    CHECK(log.skipped_count == 0);
    REQUIRE(log.samples.size() == a.samples.size() + b.samples.size());
    const double on = a.samples.back().t + kRestartGap - b.samples.front().t;
    for (gearpulse::Sample s : b.samples) {
      s.t += on;
      a.samples.push_back(s);
    }
    for (std::size_t i = 0; i < a.samples.size(); ++i) {
      CHECK(log.samples[i].t == Approx(a.samples[i].t));
      CHECK(log.samples[i].speed == Approx(a.samples[i].speed));
      CHECK(log.samples[i].freq == Approx(a.samples[i].freq));
    }
  };
  SECTION("a generic log, named columns, clock times, a Torque export: from 0, or back by an hour") {
    same_as_halves("t,speed,freq\n", "100,1,20\n101,2,21\n102,3,22\n", "0,4,23\n1,5,24\n");
    same_as_halves("t,speed,freq\n", "10,1,20\n11,2,21\n", "4,4,23\n4.5,5,24\n");  // back by 6 s
    same_as_halves("Time,Engine RPM,Speed (km/h)\n", "60,800,10\n61,900,20\n", "0,1000,30\n1,1100,40\n");
    same_as_halves("Time,Engine RPM,Speed (km/h)\n", "10:00:00,800,10\n10:00:01,900,20\n",
                   "09:00:00,1000,30\n09:00:01,1100,40\n09:00:02,1200,50\n");
    same_as_halves("Device Time,GPS Speed (Meters/second),Engine RPM(rpm)\n",
                   "10:00:00,5,800\n10:00:01,6,900\n10:00:02,7,1000\n", "09:00:00,8,1100\n09:00:01,9,1200\n");
    // Milliseconds since 1970: a second drive of the day before appended.
    same_as_halves("Time,Engine RPM,Speed (km/h)\n", "1700000000000,800,10\n1700000001000,900,20\n",
                   "1699900000000,1000,30\n1699900001000,1100,40\n");
    // Two resets: three drives.
    same_as_halves("t,speed,freq\n", "50,1,20\n51,2,21\n20,3,22\n21,4,23\n", "0,5,24\n1,6,25\n", 2);
  }
  SECTION("a Carloop log whose engine run time starts again: each drive's times as in a log of its own") {
    // Two rows a second, the counter refreshed every third row; rpm and speed change on every row, and the
    // first drive's last row and the second's first both stand still (not a held row across the restart).
    const auto drive = [](int from, int rows) {
      std::string text;
      for (int i = 0; i < rows; ++i) {
        const bool still = i == (from > 0 ? rows - 1 : 0);
        text += std::to_string(from + (i / 3) * 3 / 2) + ", " + std::to_string(still ? 0 : 1000 + 10 * i) +
                ", " + std::to_string(still ? 0 : 20 + i) + ",\n";
      }
      return text;
    };
    const std::string carloop = "ENGINE_RUN_TINE (),ENGINE_RPM (),VEHICLE_SPEED (),\n";
    const std::string first = drive(100, 40), second = drive(0, 40);
    const SampleLog run = read_log_text(carloop + first + second);
    const SampleLog a = read_log_text(carloop + first), b = read_log_text(carloop + second);
    CHECK(run.restarts == 1);
    CHECK(run.skipped_count == 0);
    REQUIRE(run.samples.size() == a.samples.size() + b.samples.size());
    for (std::size_t i = 0; i < a.samples.size(); ++i)
      CHECK(run.samples[i].t == Approx(a.samples[i].t));
    const std::size_t n = a.samples.size();
    CHECK(run.samples[n].t >=
          run.samples[n - 1].t + kRestartGap - 3.0);  // a run-time counter is up to 3 s old
    for (std::size_t i = 0; i < b.samples.size(); ++i) {
      CHECK(run.samples[n + i].t - run.samples[n].t == Approx(b.samples[i].t - b.samples[0].t));
      CHECK(run.samples[n + i].freq == Approx(b.samples[i].freq));
    }
  }
  SECTION("a small fall is rows out of order, and one row out of place a corrupt cell: bad rows as before") {
    const SampleLog jitter = read_log_text(
        "t,speed,freq\n10,1,20\n11,2,21\n12,3,22\n13,4,23\n11.5,5,24\n"
        "11.7,6,25\n14,7,26\n");
    CHECK(jitter.restarts == 0);
    REQUIRE(jitter.samples.size() == 5);
    CHECK(jitter.skipped_count == 2);
    CHECK(jitter.skipped[0] == "log.csv:6: time goes backwards (11.5 after 13)");
    const SampleLog within = read_log_text("t,speed,freq\n10,1,20\n11,2,21\n5.5,3,22\n6,4,23\n");
    CHECK(within.restarts == 0);  // 6 lies 4 s behind 10: no more than kClockReset
    CHECK(within.skipped_count == 2);
    const SampleLog one = read_log_text("t,speed,freq\n10,1,20\n11,2,21\n0,3,22\n12,4,23\n13,5,24\n");
    CHECK(one.restarts == 0);
    REQUIRE(one.skipped.size() == 1);
    CHECK(one.skipped[0] == "log.csv:4: time goes backwards (0 after 11)");
    const SampleLog ahead = read_log_text("t,speed,freq\n1,1,20\n2,2,21\n1e9,3,22\n3,4,23\n4,5,24\n");
    CHECK(ahead.restarts == 0);
    CHECK(ahead.skipped_count == 1);
    // The last row alone behind: no drive of two rows follows.
    const SampleLog last = read_log_text("t,speed,freq\n10,1,20\n11,2,21\n0,3,22\n");
    CHECK(last.restarts == 0);
    CHECK(last.skipped_count == 1);
  }
}

namespace {

// A PID-row log of an rpm and a speed read at each of `seconds`.
SampleLog pid_log(std::initializer_list<const char*> seconds) {
  std::string text = "SECONDS;PID;VALUE;UNITS\n";
  int rpm = 800;
  for (const char* t : seconds) {
    text.append(t).append(";Engine RPM;").append(std::to_string(rpm)).append(";rpm\n");
    text.append(t).append(";Speed;").append(std::to_string(rpm / 40)).append(";km/h\n");
    rpm += 100;
  }
  return read_log_text(text);
}

}  // namespace

TEST_CASE("io: a PID-row clock falling back by half a day is midnight as a time of day, else a new drive") {
  using gearpulse::kRestartGap;
  // Seconds since 1970: a drive of the day before appended (before, a day was added: still behind, dropped).
  const SampleLog epoch = pid_log({"1700000000", "1700000001", "1699900000", "1699900001"});
  CHECK(epoch.restarts == 1);
  CHECK(epoch.skipped_count == 0);
  REQUIRE(epoch.samples.size() == 4);
  CHECK(epoch.samples[2].t == Approx(epoch.samples[1].t + kRestartGap));
  CHECK(epoch.samples[2].speed == Approx(25 / 3.6));
  // A time of day back by an hour: a new drive; past midnight: the day runs on.
  const SampleLog hour = pid_log({"36000", "36001", "32400", "32401"});
  CHECK(hour.restarts == 1);
  REQUIRE(hour.samples.size() == 4);
  CHECK(hour.samples[2].t == Approx(1 + kRestartGap));
  const SampleLog midnight = pid_log({"86398", "86399", "1", "2"});
  CHECK(midnight.restarts == 0);
  REQUIRE(midnight.samples.size() == 4);
  CHECK(midnight.samples[2].t == Approx(3));
}
