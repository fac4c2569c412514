// The log readers on generic CSV: bad rows and files, delimiters and quotes, the real logs, mangled logs.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
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

TEST_CASE("io: empty, headerless and useless files are one-line errors") {
  CHECK(error_of("") == "log.csv: empty file");
  // A log written newest first: every row but one went back in time and was dropped, and the one left
  // was fitted as a log with nothing to learn from.
  CHECK(error_of("t,speed,freq\n3,10,50\n2,9,45\n1,8,40\n0,7,35\n") ==
        "log.csv: 3 of 4 rows go back in time (the first: time goes backwards (2 after 3)): written newest "
        "first? Sort the log by time, oldest first");
  CHECK(error_of("Time (s),Engine RPM (rpm),Vehicle Speed (km/h)\n3,1500,10\n2,1400,9\n1,1300,8\n")
            .rfind("log.csv: 2 of 3 rows go back in time", 0) == 0);
  CHECK(error_of("\n\n") == "log.csv: empty file");
  CHECK(error_of("1,2,3\n4,5,6\n").rfind("log.csv:1: unrecognised header", 0) == 0);
  // A car's log without one of the two readings says which one to log; every format is in the list.
  const std::string no_rpm = error_of("Time (s),Vehicle Speed (km/h),Throttle\n0,10,5\n");
  CHECK(no_rpm.rfind("log.csv:1: unrecognised header", 0) == 0);
  CHECK(no_rpm.find("no column's name holds 'rpm' (the engine speed): log the engine RPM") !=
        std::string::npos);
  CHECK(no_rpm.find("SECONDS,PID,VALUE rows") != std::string::npos);
  const std::string no_speed = error_of("Time (s),Engine RPM,Throttle\n0,800,5\n");
  CHECK(no_speed.find("no column's name holds 'speed'") != std::string::npos);
  CHECK(error_of("1,2,3\n4,5,6\n").find("no column's name") == std::string::npos);
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
