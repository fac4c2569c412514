// `gearpulse-devtools simulate` and `gearpulse-devtools feed`, run as the built binary.
#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "drivers/unique_fd.hpp"
#include "tests/test_util.hpp"

namespace fs = std::filesystem;

using gearpulse::test::TempDir;

namespace {

const std::string kCli = GEARPULSE_BINARY_DIR "/tools/gearpulse-devtools";

using Result = gearpulse::test::ShellResult;

// Runs a shell command, stdout and stderr captured together.
Result run(const std::string& command) {
  return gearpulse::test::run_shell(command + " 2>&1");
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<std::vector<std::string>> csv_rows(const fs::path& p) {
  std::ifstream in(p);
  std::string line;
  std::vector<std::vector<std::string>> rows;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ','))
      cells.push_back(cell);
    if (!line.empty() && line.back() == ',') cells.emplace_back();
    rows.push_back(cells);
  }
  return rows;
}

std::uint32_t le32(const std::string& s, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i)
    v = (v << 8) | static_cast<unsigned char>(s[at + static_cast<std::size_t>(i)]);
  return v;
}

// Waits for a feeder started with popen and requires that it exited with status 0.
void check_exit_ok(std::FILE* feeder) {
  const int rc = ::pclose(feeder);
  CHECK(WIFEXITED(rc));
  CHECK(WEXITSTATUS(rc) == 0);
}

}  // namespace

TEST_CASE("simulate: writes a drive whose files agree with each other", "[simulate]") {
  TempDir dir;
  const Result r = run(kCli + " simulate --out " + dir.path().string() +
                       " --seed 5 --duration 60 --outage 20:15 --rate 8000");
  INFO(r.out);
  REQUIRE(r.status == 0);
  CHECK(r.out.find("km") != std::string::npos);

  // truth.csv: header, rows every 0.1 s, the car starts and ends at rest.
  const auto truth = csv_rows(dir.path() / "truth.csv");
  REQUIRE(truth.size() > 100);
  CHECK(truth[0] == std::vector<std::string>{"t", "speed", "freq", "gear"});
  CHECK(std::stod(truth[1][1]) == Approx(0.0).margin(1e-9));
  double distance = 0.0, max_speed = 0.0;
  for (std::size_t i = 2; i < truth.size(); ++i) {
    const double dt = std::stod(truth[i][0]) - std::stod(truth[i - 1][0]);
    distance += 0.5 * (std::stod(truth[i][1]) + std::stod(truth[i - 1][1])) * dt;
    max_speed = std::max(max_speed, std::stod(truth[i][1]));
  }
  const double length = std::stod(truth.back()[0]);
  CHECK(length >= 60.0);
  CHECK(max_speed > 3.0);

  // Audio: raw S16 and a WAV with the same samples, length = drive length at the rate.
  const std::string raw = slurp(dir.path() / "drive.raw");
  const std::string wav = slurp(dir.path() / "drive.wav");
  CHECK(static_cast<double>(raw.size()) == Approx(length * 8000 * 2).margin(2 * 8000 * 0.2));
  REQUIRE(wav.size() == raw.size() + 44);
  CHECK(wav.substr(0, 4) == "RIFF");
  CHECK(le32(wav, 24) == 8000);
  CHECK(le32(wav, 40) == raw.size());
  CHECK(wav.substr(44) == raw);

  // samples.csv: 1 Hz, speed blank exactly inside the outage, freq everywhere.
  const auto samples = csv_rows(dir.path() / "samples.csv");
  REQUIRE(samples.size() > 60);
  CHECK(samples[0] == std::vector<std::string>{"t", "speed", "freq"});
  for (std::size_t i = 1; i < samples.size(); ++i) {
    const double t = std::stod(samples[i][0]);
    INFO("samples.csv row " << i + 1);
    REQUIRE(samples[i].size() == 3);
    CHECK(samples[i][1].empty() == (t >= 20.0 && t < 35.0));
    CHECK(!samples[i][2].empty());
  }

  // NMEA: two sentences per second from 8 s (the default GPS lead) before t = 0, which is 12:00:00 UTC;
  // void fixes exactly inside the outage.
  std::ifstream nmea(dir.path() / "drive.nmea");
  std::string line;
  int gga = 0, rmc = 0, void_rmc = 0;
  std::string first_rmc;
  bool has_t0 = false;
  while (std::getline(nmea, line)) {
    if (line.rfind("$GPGGA", 0) == 0) ++gga;
    if (line.rfind("$GPRMC", 0) == 0) {
      ++rmc;
      if (first_rmc.empty()) first_rmc = line;
      if (line.find(",V,") != std::string::npos) ++void_rmc;
      has_t0 = has_t0 || line.rfind("$GPRMC,120000.00,A,", 0) == 0;
    }
  }
  CHECK(gga == rmc);
  CHECK(rmc == static_cast<int>(samples.size()) - 1 + 8);
  CHECK(first_rmc.rfind("$GPRMC,115952.00,A,", 0) == 0);
  CHECK(has_t0);
  CHECK(void_rmc == 15);

  // drive.env agrees with the truth.
  const std::string env = slurp(dir.path() / "drive.env");
  const auto at = env.find("distance_m=");
  REQUIRE(at != std::string::npos);
  CHECK(std::stod(env.substr(at + 11)) == Approx(distance).epsilon(1e-3));
}

TEST_CASE("simulate: the same seed gives the same drive and another seed another", "[simulate]") {
  TempDir dir;
  const auto sim = [&](const std::string& sub, int seed) {
    return run(kCli + " simulate --out " + (dir.path() / sub).string() +
               " --duration 30 --rate 8000 --seed " + std::to_string(seed))
        .status;
  };
  REQUIRE(sim("a", 3) == 0);
  REQUIRE(sim("b", 3) == 0);
  REQUIRE(sim("c", 4) == 0);
  CHECK(slurp(dir.path() / "a" / "drive.raw") == slurp(dir.path() / "b" / "drive.raw"));
  CHECK(slurp(dir.path() / "a" / "truth.csv") == slurp(dir.path() / "b" / "truth.csv"));
  CHECK(slurp(dir.path() / "a" / "truth.csv") != slurp(dir.path() / "c" / "truth.csv"));
}

// The value of KEY=VALUE in drive.env's text, or "" if absent.
std::string env_value(const std::string& env, const std::string& key) {
  const auto at = env.find(key + "=");
  if (at == std::string::npos) return {};
  const auto from = at + key.size() + 1;
  return env.substr(from, env.find('\n', from) - from);
}

TEST_CASE("simulate: --outage-at-skip starts the outage at the first braking skip-downshift", "[simulate]") {
  TempDir dir;
  const auto sim = [&](const std::string& sub, const std::string& args) {
    return run(kCli + " simulate --no-audio --out " + (dir.path() / sub).string() + " " + args);
  };
  const Result r = sim("skip", "--seed 1 --duration 150 --skip-downshift 1 --outage-at-skip 60");
  INFO(r.out);
  REQUIRE(r.status == 0);
  CHECK(r.out.find("outage at the braking skip") != std::string::npos);
  const std::string env = slurp(dir.path() / "skip" / "drive.env");
  const double clutch_out = std::stod(env_value(env, "skip_clutch_out_s"));
  const double start = std::stod(env_value(env, "outage_start_s"));
  CHECK(start == std::ceil(clutch_out));
  CHECK(std::stod(env_value(env, "outage_length_s")) == 60.0);
  const std::string gears = env_value(env, "skip_gears");  // FROM:TO
  const int from = std::stoi(gears), to = std::stoi(gears.substr(gears.find(':') + 1));
  CHECK(to <= from - 2);

  // The truth: FROM engaged and the car braking before the clutch goes out, TO engaged after it.
  const auto truth = csv_rows(dir.path() / "skip" / "truth.csv");
  double before = -1.0, at_out = -1.0;
  int gear_before = -1, gear_after = -1;
  for (std::size_t i = 1; i < truth.size(); ++i) {
    const double t = std::stod(truth[i][0]);
    if (std::abs(t - (clutch_out - 1.0)) < 0.05) before = std::stod(truth[i][1]);
    if (std::abs(t - clutch_out) < 0.05) at_out = std::stod(truth[i][1]);
    if (gear_before < 0 && t >= clutch_out - 0.15) gear_before = std::stoi(truth[i][3]);
    if (gear_after < 0 && t >= clutch_out + 1.7) gear_after = std::stoi(truth[i][3]);
  }
  CHECK(gear_before == from);
  CHECK(gear_after == to);
  CHECK(before - at_out > 1.0);  // m/s lost over the second before: braking

  // The samples blank the speed over the outage, as with --outage START:LEN; the drive is repeatable.
  for (const auto& row : csv_rows(dir.path() / "skip" / "samples.csv")) {
    if (row[0] == "t") continue;
    const double t = std::stod(row[0]);
    CHECK(row[1].empty() == (t >= start && t < start + 60.0));
  }
  REQUIRE(sim("again", "--seed 1 --duration 150 --skip-downshift 1 --outage-at-skip 60").status == 0);
  CHECK(slurp(dir.path() / "again" / "truth.csv") == slurp(dir.path() / "skip" / "truth.csv"));

  // --skip-drive-on: a skip after which the lower gear stays engaged for 10 s.
  const Result on = sim("on",
                        "--style highway --seed 1 --duration 150 --skip-downshift 1 --outage-at-skip 60 "
                        "--skip-drive-on");
  INFO(on.out);
  REQUIRE(on.status == 0);
  const std::string on_env = slurp(dir.path() / "on" / "drive.env");
  const double on_out = std::stod(env_value(on_env, "skip_clutch_out_s"));
  const int on_to = std::stoi(env_value(on_env, "skip_gears").substr(2));
  int engaged = 0;
  for (const auto& row : csv_rows(dir.path() / "on" / "truth.csv")) {
    if (row[0] == "t") continue;
    const double t = std::stod(row[0]);
    if (t > on_out + 1.7 && t < on_out + 11.0) engaged += std::stoi(row[3]) == on_to ? 1 : -1000;
  }
  CHECK(engaged > 80);

  // Without a skip that leaves room for the outage before the drive's end: refused.
  CHECK(sim("none", "--seed 1 --duration 60 --skip-downshift 1 --outage-at-skip 60").status == 2);
}

TEST_CASE("simulate: --gps-hz 10 writes ten fix sets a second, times to the tenth, the same drive",
          "[simulate]") {
  TempDir dir;
  const std::string common = " --seed 5 --duration 60 --outage 20:15 --no-audio --out ";
  REQUIRE(run(kCli + " simulate" + common + (dir.path() / "one").string()).status == 0);
  const Result r = run(kCli + " simulate --gps-hz 10" + common + (dir.path() / "ten").string());
  INFO(r.out);
  REQUIRE(r.status == 0);
  CHECK(slurp(dir.path() / "ten" / "truth.csv") == slurp(dir.path() / "one" / "truth.csv"));
  CHECK(slurp(dir.path() / "ten" / "drive.env").find("gps_hz=10") != std::string::npos);
  std::vector<std::string> one, ten;
  for (const auto& [name, rmc] : {std::pair{"one", &one}, std::pair{"ten", &ten}}) {
    std::ifstream nmea(dir.path() / name / "drive.nmea");
    for (std::string line; std::getline(nmea, line);)
      if (line.rfind("$GPRMC", 0) == 0) rmc->push_back(line);
  }
  // From 8 s before t = 0 to the drive's end: past the last whole second, its tenths up to the end.
  REQUIRE(ten.size() > 10 * (one.size() - 1));
  REQUIRE(ten.size() < 10 * one.size());
  CHECK(ten[0].rfind("$GPRMC,115952.00,A,", 0) == 0);
  CHECK(ten[1].rfind("$GPRMC,115952.10,A,", 0) == 0);
  CHECK(ten[9].rfind("$GPRMC,115952.90,A,", 0) == 0);
  CHECK(ten[80].rfind("$GPRMC,120000.00,A,", 0) == 0);
  int void_rmc = 0;
  for (const std::string& line : ten)
    void_rmc += line.find(",V,") != std::string::npos;
  CHECK(void_rmc == 150);
}

TEST_CASE("simulate: bad options are refused with exit 2", "[simulate]") {
  TempDir dir;
  const std::string out = " --out " + (dir.path() / "x").string();
  for (const std::string args : {" --outage 20",
                                 " --outage a:5",
                                 " --outage 10:-3",
                                 " --outage 10:1e308",
                                 " --vehicle nosuchcar",
                                 " --style racing",
                                 " --duration 2",
                                 " --duration 1e308",
                                 " --rate 10",
                                 " --snr nan",
                                 " --tone 1e9",
                                 " --tone nan",
                                 " --pulses-per-km -5",
                                 " --duration 60 --outage 1000:10",
                                 " --seed -1",
                                 " --seed 99999999999999999999",
                                 " --skip-downshift 2",
                                 " --outage-at-skip 60",
                                 " --skip-downshift 1 --outage-at-skip 60 --outage 10:5",
                                 " --skip-drive-on",
                                 " --skip-downshift nan",
                                 " --gps-hz 3",
                                 " --gps-hz 0"}) {
    const Result r = run(kCli + " simulate" + out + args);
    INFO(args << ": " << r.out);
    CHECK(r.status == 2);
    CHECK(r.out.find("gearpulse-devtools:") != std::string::npos);
  }
  CHECK(!fs::exists(dir.path() / "x" / "drive.raw"));
}

TEST_CASE("feed: a FIFO reader gets the file bit-exact in whole periods at real-time pace", "[feed]") {
  TempDir dir;
  const fs::path in = dir.path() / "in.raw", fifo = dir.path() / "fifo";
  // 0.5 s at 8 kHz, 3 channels: 4000 frames, not a whole number of 256-frame periods.
  std::string data;
  for (int i = 0; i < 4000 * 3; ++i) {
    const auto v = static_cast<std::int16_t>((i * 37) % 65536 - 32768);
    data.push_back(static_cast<char>(v & 0xff));
    data.push_back(static_cast<char>((v >> 8) & 0xff));
  }
  std::ofstream(in, std::ios::binary) << data;
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);

  const auto start = std::chrono::steady_clock::now();
  std::FILE* feeder = ::popen((kCli + " feed --quiet --period 256 --rate 8000 --channels 3 " + in.string() +
                               " " + fifo.string() + " 2>&1")
                                  .c_str(),
                              "r");
  REQUIRE(feeder != nullptr);
  gearpulse::UniqueFd reader(::open(fifo.c_str(), O_RDONLY));
  REQUIRE(reader);
  const int fd = reader.get();
  std::string got;
  char buf[8192];
  ssize_t n = 0;
  while ((n = ::read(fd, buf, sizeof buf)) > 0)
    got.append(buf, static_cast<std::size_t>(n));
  reader.reset();
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  check_exit_ok(feeder);
  // 16 whole periods: the file, then silence up to the period boundary.
  REQUIRE(got.size() == 16u * 256 * 3 * 2);
  CHECK(got.substr(0, data.size()) == data);
  CHECK(got.find_first_not_of('\0', data.size()) == std::string::npos);
  // Paced: the last period cannot be out before its deadline (a lower bound, never flaky).
  CHECK(elapsed >= 15.0 * 256 / 8000);
}

// The harness opens the capture before the drive starts: whatever the feeder writes before the capture
// reads waits in the FIFO, unseen by ALSA, and read at once it set the capture's sample clock ahead of
// real time, which then held the audio back 1.5 s for the whole drive (bench/daemon_outages.sh). With
// --wait-start nothing is written before SIGUSR1, and the FIFO holds one page.
TEST_CASE("feed: with --wait-start nothing is written before SIGUSR1, and the FIFO holds a page", "[feed]") {
  TempDir dir;
  const fs::path in = dir.path() / "in.raw", fifo = dir.path() / "fifo", pid = dir.path() / "pid";
  std::ofstream(in, std::ios::binary) << std::string(8 * 256 * 2, '\x11');  // 8 periods, 0.256 s at 8 kHz
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  std::FILE* feeder = ::popen(
      ("sh -c 'echo $$ >" + pid.string() + "; exec " + kCli +
       " feed --quiet --wait-start --period 256 --rate 8000 " + in.string() + " " + fifo.string() + "' 2>&1")
          .c_str(),
      "r");
  REQUIRE(feeder != nullptr);
  gearpulse::UniqueFd reader(::open(fifo.c_str(), O_RDONLY | O_NONBLOCK));
  REQUIRE(reader);
  const int fd = reader.get();
  // The feeder says when it has opened and shrunk the FIFO and waits for the signal (EOF if it failed).
  char line[512] = {};
  REQUIRE(std::fgets(line, sizeof line, feeder) != nullptr);
  INFO(line);
  REQUIRE(std::string(line).find("FIFO open, waiting for SIGUSR1") != std::string::npos);
  pollfd p{fd, POLLIN, 0};
  CHECK(::poll(&p, 1, 200) == 0);  // nothing written before the signal
  const int size = ::fcntl(fd, F_GETPIPE_SZ);
  CHECK(size > 0);
  CHECK(size <= ::sysconf(_SC_PAGESIZE));
  REQUIRE(fs::exists(pid));
  const pid_t feeder_pid = std::stoi(slurp(pid));
  REQUIRE(::kill(feeder_pid, SIGUSR1) == 0);
  const auto start = std::chrono::steady_clock::now();
  std::string got;
  char buf[8192];
  while (::poll(&p, 1, 2000) > 0) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n <= 0) break;  // the writer closed
    got.append(buf, static_cast<std::size_t>(n));
  }
  reader.reset();
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  check_exit_ok(feeder);
  CHECK(got == slurp(in));
  CHECK(elapsed >= 7.0 * 256 / 8000);  // paced from the signal
}

TEST_CASE("feed: a missing input or a bad format is an error", "[feed]") {
  TempDir dir;
  Result r = run(kCli + " feed " + (dir.path() / "none.raw").string() + " " + (dir.path() / "fifo").string());
  CHECK(r.status == 2);
  CHECK(r.out.find("none.raw") != std::string::npos);
  std::ofstream(dir.path() / "odd.raw", std::ios::binary) << "abc";
  r = run(kCli + " feed " + (dir.path() / "odd.raw").string() + " " + (dir.path() / "fifo").string());
  CHECK(r.status == 2);
  CHECK(r.out.find("odd.raw") != std::string::npos);
  r = run(kCli + " feed --format s24 " + (dir.path() / "odd.raw").string() + " x");
  CHECK(r.status == 2);
  r = run(kCli + " feed " + dir.path().string() + " x");
  CHECK(r.status == 2);
  CHECK(r.out.find("is a directory") != std::string::npos);
  // Sizes that overflow a frame's byte count are refused, not divided by.
  for (const char* size : {" --channels 1073741824", " --channels 536870912", " --period 2147483647"}) {
    r = run(kCli + " feed --format s32" + size + " " + (dir.path() / "odd.raw").string() + " x");
    INFO(size << ": " << r.out);
    CHECK(r.status == 2);
    // The message names the option that is out of range, not all three.
    CHECK(r.out.find(std::string(size).substr(1, std::string(size).find(' ', 1) - 1) + " ") !=
          std::string::npos);
    CHECK(r.out.find("is out of range") != std::string::npos);
  }
}
