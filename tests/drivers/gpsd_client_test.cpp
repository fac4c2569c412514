// GpsdClient against a real gpsd started by gpsfake: the speeds it delivers, implausible fixes, gpsd
// starting late, killed and restarted, and a client thread held up. gpsd_backoff_test.cpp has the client
// against an absent or misbehaving gpsd.
#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

#include "drivers/clock.hpp"
#include "drivers/gpsd_client.hpp"
#include "tests/drivers/gpsd_endpoints.hpp"
#include "tests/drivers/gpsfake.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/nmea.hpp"

using namespace std::chrono_literals;
using gearpulse::GpsdClient;
using gearpulse::GpsdConfig;
using gearpulse::GpsdState;
using gearpulse::GpsReport;
using gearpulse::test::config_for;
using gearpulse::test::GpsFake;
using gearpulse::test::Recorder;
using gearpulse::test::TempDir;
using gearpulse::test::wait_for;

namespace {

constexpr double kKnot = 1852.0 / 3600.0;

// Each of these tests repeats its log: gpsfake feeds from the moment gpsd listens, and under a loaded
// sanitizer run the client has joined a log fed once only after its last epoch. Once a whole pass has
// arrived, gpsfake is stopped and the reports already sent are let in, so that the newest report stays
// the newest for the freshness checks.
void hold_after_pass(GpsFake& fake, Recorder& rec) {
  fake.pause();
  std::size_t seen = rec.size();
  while (true) {
    std::this_thread::sleep_for(500ms);
    const std::size_t now = rec.size();
    if (now == seen) return;
    seen = now;
  }
}

double utc_of(int y, int mo, int d, int h, int mi, int s) {
  std::tm tm{};
  tm.tm_year = y - 1900;
  tm.tm_mon = mo - 1;
  tm.tm_mday = d;
  tm.tm_hour = h;
  tm.tm_min = mi;
  tm.tm_sec = s;
  return static_cast<double>(::timegm(&tm));
}

// A generated drive: `speeds` at 1 Hz of log time (NaN = outage) written as NMEA.
std::filesystem::path write_log(const TempDir& dir, const std::vector<double>& speeds) {
  const auto path = dir / "drive.nmea";
  gearpulse::sim::write_nmea_log(path, gearpulse::sim::epochs_at_1hz(speeds));
  return path;
}

}  // namespace

TEST_CASE("gpsd: generated NMEA speeds arrive within NMEA precision and an outage is no GPS") {
  TempDir dir;
  const double nan = std::nan("");
  // A lead-in at 5 m/s covers gpsd's start (gpsfake feeds before gpsd has opened its device).
  const std::vector<double> speeds = {5.0, 5.0, 5.0, 5.0, 5.0, 3.7,  8.25,  13.9, 22.22, 27.5, 31.1, 33.3,
                                      nan, nan, nan, nan, nan, 17.3, 12.05, 9.4,  4.44,  0.0,  0.0,  2.5};
  const auto log = write_log(dir, speeds);
  const int port = gearpulse::test::free_port();
  GpsFake fake(log, port, 0.1, false);  // 5 epochs per second of real time
  REQUIRE(GpsFake::wait_listening(port, 10s));
  Recorder rec;
  GpsdClient client(config_for(port), rec.callback());
  client.start();
  const double t0 = utc_of(2026, 1, 15, 12, 0, 0);  // NmeaTrack's default date and time of day
  const double last_fix = t0 + static_cast<double>(speeds.size()) - 1.0;
  REQUIRE(wait_for([&] { return rec.saw_pass(t0 + 4.0, last_fix); }, 20s));
  // The freshness checks below want a usable newest report: held in the lead-in of the next pass, or
  // let go on to one if the hold fell in its outage.
  hold_after_pass(fake, rec);
  for (int tries = 0; tries < 5 && !client.latest()->usable(); ++tries) {
    fake.resume();
    REQUIRE(wait_for([&] { return client.latest()->usable(); }, 10s));
    hold_after_pass(fake, rec);
  }
  std::size_t checked = 0, outage_reports = 0;
  for (const GpsReport& r : rec.snapshot()) {
    if (!std::isfinite(r.fix_time)) {
      CHECK_FALSE(r.usable());
      continue;
    }
    const long epoch = std::lround(r.fix_time - t0);
    REQUIRE(epoch >= 0);
    REQUIRE(epoch < static_cast<long>(speeds.size()));
    const double want = speeds[static_cast<std::size_t>(epoch)];
    if (std::isnan(want)) {
      CHECK_FALSE(r.usable());
      ++outage_reports;
    } else if (r.usable()) {
      // RMC carries knots with 3 decimals, gpsd's JSON m/s with 3 decimals.
      CHECK(std::fabs(r.speed - want) <= 0.0005 * kKnot + 0.0005 + 1e-9);
      ++checked;
    }
  }
  CHECK(checked >= 8);
  // During the outage gpsd reports no fix (or nothing at all, which the timeout turns into no GPS).
  const auto all = rec.snapshot();
  const bool saw_no_fix = outage_reports > 0 ||
                          std::any_of(all.begin(), all.end(), [](const GpsReport& r) { return r.mode == 1; });
  CHECK(saw_no_fix);
  // Freshness: the newest report is GPS when just received, and "no GPS" once older than the timeout.
  const auto newest = client.latest();
  REQUIRE(newest);
  REQUIRE(newest->usable());
  CHECK(client.has_gps(newest->rx_ns));
  CHECK(client.has_gps(newest->rx_ns + 1'400'000'000));
  CHECK_FALSE(client.has_gps(newest->rx_ns + 1'600'000'000));
  CHECK(client.status().connects == 1);
}

TEST_CASE("gpsd: GPS at a past time is the report newest then, after GPS was lost and came back") {
  // The tracker thread may step a hop after its time (a backlog drained late): it asks for GPS at the
  // moment the hop was due, which must be what was received by then, not the newest report.
  TempDir dir;
  const double nan = std::nan("");
  const std::vector<double> speeds = {5.0, 5.0, 5.0, 5.0, 5.0, 12.0, 12.0, 12.0, 12.0, nan,
                                      nan, nan, nan, nan, nan, 20.0, 20.0, 20.0, 20.0, 20.0};
  const auto log = write_log(dir, speeds);
  const int port = gearpulse::test::free_port();
  GpsFake fake(log, port, 0.1, false);
  REQUIRE(GpsFake::wait_listening(port, 10s));
  Recorder rec;
  GpsdClient client(config_for(port), rec.callback());
  client.start();
  const double t0 = utc_of(2026, 1, 15, 12, 0, 0);
  REQUIRE(
      wait_for([&] { return rec.saw_pass(t0 + 4.0, t0 + static_cast<double>(speeds.size()) - 1.0); }, 20s));
  hold_after_pass(fake, rec);
  const auto all = rec.snapshot();
  REQUIRE(all.size() >= 2);
  const std::size_t kept = std::min(all.size(), gearpulse::GpsHistory::kSize);
  std::size_t usable = 0, no_fix = 0;
  for (std::size_t i = all.size() - kept; i < all.size(); ++i) {
    const GpsReport& r = all[i];
    // Due at its receive time and stepped after it (late): the report of that time, judged then.
    const auto then = client.for_hop(r.rx_ns, r.rx_ns + 1).fix;
    CHECK(then.has_value() == r.usable());
    if (then) {
      CHECK(then->rx_ns == r.rx_ns);
      CHECK(then->speed == r.speed);
      ++usable;
    } else {
      ++no_fix;
    }
  }
  CHECK(usable >= 8);
  CHECK(no_fix >= 1);
  // Now, and for a hop on time, the newest report counts, as it always did.
  const auto newest = client.latest();
  REQUIRE(newest);
  CHECK(client.has_gps(newest->rx_ns + 1'400'000'000) == newest->usable());
  const auto on_time = client.for_hop(newest->rx_ns + 1'400'000'000, newest->rx_ns + 1'400'000'000);
  CHECK_FALSE(on_time.late);
  CHECK(on_time.fix.has_value() == newest->usable());
}

// A receiver's glitch (a multipath spike, a bad epoch) once went straight to the pulse train: 300 m/s for
// five epochs is 1.5 km of pulses. Such fixes are published without a speed and counted.
TEST_CASE("gpsd: a speed no car reaches, or not that fast, is published as none and counted") {
  TempDir dir;
  // Ends at the speed it starts with: the repeated log runs on without a step of its own.
  const std::vector<double> speeds = {10.0, 10.0, 10.0, 10.0, 10.0, 10.5, 300.0, 300.0, 11.0,
                                      11.5, 60.0, 12.0, 12.5, 13.0, 13.0, 12.0,  11.0,  10.0};
  const auto log = write_log(dir, speeds);
  const int port = gearpulse::test::free_port();
  GpsFake fake(log, port, 0.2, false);  // 2.5 epochs a second (at 5, a loaded TSan run got 9 of 14)
  REQUIRE(GpsFake::wait_listening(port, 10s));
  // Each report with the count of refused speeds when it was published (counted before it, so its own
  // refusal included).
  std::mutex mutex;
  std::vector<std::pair<GpsReport, std::uint64_t>> seen;
  std::atomic<const GpsdClient*> counter{nullptr};
  Recorder rec;
  GpsdClient client(config_for(port), [&](const GpsReport& r) {
    rec.callback()(r);
    std::lock_guard lock(mutex);
    seen.emplace_back(r, counter.load()->status().implausible);
  });
  counter = &client;
  client.start();
  const double t0 = utc_of(2026, 1, 15, 12, 0, 0);
  REQUIRE(
      wait_for([&] { return rec.saw_pass(t0 + 4.0, t0 + static_cast<double>(speeds.size()) - 1.0); }, 30s));
  hold_after_pass(fake, rec);
  std::lock_guard lock(mutex);
  // Judged from the first pass the client saw from its lead-in: one that joined mid-pass judged its
  // first speeds with no reference (a 60 m/s first fix is no glitch to it).
  const auto start = std::find_if(seen.begin(), seen.end(), [&](const auto& s) {
    return std::isfinite(s.first.fix_time) && s.first.fix_time <= t0 + 4.0;
  });
  REQUIRE(start != seen.end());
  const std::uint64_t refused_before = start == seen.begin() ? 0 : std::prev(start)->second;
  std::size_t spikes_seen = 0, good_seen = 0;
  for (auto it = start; it != seen.end(); ++it) {
    const GpsReport& r = it->first;
    if (!std::isfinite(r.fix_time)) continue;
    const auto epoch = static_cast<std::size_t>(std::lround(r.fix_time - t0));
    REQUIRE(epoch < speeds.size());
    const bool spike = epoch == 6 || epoch == 7 || epoch == 10;
    if (spike) {
      CHECK_FALSE(r.usable());
      ++spikes_seen;
    } else if (it != seen.begin() && r.mode >= 2) {  // gpsd's first report may carry no speed yet
      CHECK(r.usable());
      ++good_seen;
    }
  }
  CHECK(spikes_seen >= 2);  // gpsd may merge or drop an epoch under gpsfake's pace
  CHECK(good_seen >= 10);
  CHECK(client.status().implausible - refused_before == spikes_seen);
  CHECK(client.status().last_implausible > 50.0);
}

TEST_CASE("gpsd: keeps trying while gpsd is absent and connects once it starts") {
  TempDir dir;
  std::vector<double> speeds(40, 12.5);
  const auto log = write_log(dir, speeds);
  const int port = gearpulse::test::free_port();
  GpsdClient client(config_for(port));
  client.start();
  REQUIRE(wait_for([&] { return client.status().failures >= 3; }, 10s));
  const auto absent = client.status();
  CHECK(absent.state == GpsdState::kConnecting);
  CHECK(absent.connects == 0);
  CHECK(absent.last_error.find(std::to_string(port)) != std::string::npos);
  CHECK_FALSE(client.has_gps(gearpulse::monotonic_ns()));
  CHECK_FALSE(client.latest());

  GpsFake fake(log, port, 0.05, false);
  // On a failure: whether gpsd listens, what gpsfake wrote, and where the client stands.
  if (!wait_for([&] { return client.has_gps(gearpulse::monotonic_ns()); }, 20s))
    FAIL("no fix: " << fake.describe() << "; client " << gearpulse::to_string(client.status().state) << ", "
                    << client.status().connects << " connects, last error '" << client.status().last_error
                    << "'");
  CHECK(client.status().state == GpsdState::kConnected);
  CHECK(client.latest()->speed == Approx(12.5).margin(0.001));
}

TEST_CASE("gpsd: reconnects after gpsd is killed mid-stream and started again") {
  TempDir dir;
  std::vector<double> speeds(40, 7.25);
  const auto log = write_log(dir, speeds);
  const int port = gearpulse::test::free_port();
  auto fake = std::make_unique<GpsFake>(log, port, 0.05, false);
  REQUIRE(GpsFake::wait_listening(port, 10s));
  GpsdClient client(config_for(port));
  client.start();
  REQUIRE(wait_for([&] { return client.has_gps(gearpulse::monotonic_ns()); }, 20s));
  const auto before = client.status();
  CHECK(before.connects == 1);

  fake->kill();  // SIGKILL: gpsd vanishes without closing anything politely
  REQUIRE(wait_for([&] { return client.status().state == GpsdState::kConnecting; }, 10s));
  const std::int64_t killed_at = gearpulse::monotonic_ns();
  CHECK(client.status().failures > before.failures);
  // No reports while gpsd is dead: after the no-fix timeout it is "no GPS".
  CHECK_FALSE(client.has_gps(killed_at + 1'600'000'000));

  const auto reports_dead = client.status().reports;
  fake = std::make_unique<GpsFake>(log, port, 0.05, false);
  REQUIRE(wait_for([&] { return client.status().reports > reports_dead + 2; }, 20s));
  CHECK(client.status().connects == 2);
  CHECK(client.has_gps(gearpulse::monotonic_ns()));
  CHECK(client.latest()->speed == Approx(7.25).margin(0.001));
  client.stop();
  CHECK(client.status().state == GpsdState::kStopped);
}

namespace {

// RMC speeds of a real log, keyed by UTC centisecond of day.
std::map<long, double> rmc_speeds(const std::filesystem::path& path) {
  std::map<long, double> out;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    if (line.size() < 7 || line.compare(3, 3, "RMC") != 0) continue;
    std::vector<std::string> fields;
    std::stringstream ss(line);
    std::string field;
    while (std::getline(ss, field, ','))
      fields.push_back(field);
    if (fields.size() < 8 || fields[2] != "A" || fields[1].size() < 6 || fields[7].empty()) continue;
    const double sod = std::stol(fields[1].substr(0, 2)) * 3600 + std::stol(fields[1].substr(2, 2)) * 60 +
                       std::stod(fields[1].substr(4));
    out[std::lround(sod * 100)] = std::stod(fields[7]) * kKnot;
  }
  return out;
}

}  // namespace

TEST_CASE("gpsd: real receiver logs deliver their RMC speeds") {
  const std::filesystem::path base = gearpulse::test::real_data_dir() / "gpsd-nmea";
  if (!std::filesystem::exists(base / "nl2008u.log"))
    GEARPULSE_SKIP_TEST("real gpsd logs not found at " << base);
  for (const char* name : {"nl2008u.log", "bt451.log"}) {
    INFO(name);
    const auto log = base / name;
    const auto truth = rmc_speeds(log);
    REQUIRE(truth.size() >= 3);
    const int port = gearpulse::test::free_port();
    GpsFake fake(log, port, 0.01, false);  // repeats the log: the start gpsd misses comes round again
    REQUIRE(GpsFake::wait_listening(port, 10s));
    Recorder rec;
    GpsdClient client(config_for(port), rec.callback());
    client.start();
    REQUIRE(wait_for([&] { return rec.usable() >= 6; }, 20s));
    client.stop();
    std::size_t matched = 0;
    for (const GpsReport& r : rec.snapshot()) {
      if (!r.usable() || !std::isfinite(r.fix_time)) continue;
      const auto it = truth.find(std::lround(std::fmod(r.fix_time, 86400.0) * 100));
      if (it == truth.end()) continue;  // a fix from another sentence of the same second
      INFO("fix time " << std::fixed << r.fix_time);
      CHECK(r.speed == Approx(it->second).margin(0.0006));
      ++matched;
    }
    CHECK(matched >= 3);
  }
}

TEST_CASE("gpsd: a client thread held up stops beating and beats again once it is free") {
  TempDir dir;
  const auto log = write_log(dir, std::vector<double>(40, 9.0));
  const int port = gearpulse::test::free_port();
  GpsFake fake(log, port, 0.05, false);
  REQUIRE(GpsFake::wait_listening(port, 10s));
  // The report callback runs on the client thread: holding it there is a hung client.
  std::mutex mutex;
  std::condition_variable cv;
  bool release = false;
  std::atomic<bool> held{false};
  GpsdClient client(config_for(port), [&](const GpsReport&) {
    std::unique_lock lock(mutex);
    held = true;
    cv.wait(lock, [&] { return release; });
  });
  client.start();
  REQUIRE(wait_for([&] { return held.load(); }, 20s));
  const std::int64_t h1 = client.heartbeat_ns();
  std::this_thread::sleep_for(300ms);  // a connected client beats every 100 ms at least
  CHECK(client.heartbeat_ns() == h1);
  {
    std::lock_guard lock(mutex);
    release = true;
  }
  cv.notify_all();
  REQUIRE(wait_for([&] { return client.heartbeat_ns() > h1; }, 10s));
  client.stop();
}

// A gpsd that dies is said at once: the status (and the daemon's "disconnected") must not go on saying
// connected through the wait before the next attempt.
TEST_CASE("gpsd: a lost connection is shown as connecting during the wait before the reconnect") {
  TempDir dir;
  const auto log = write_log(dir, std::vector<double>(40, 8.0));
  const int port = gearpulse::test::free_port();
  GpsFake fake(log, port, 0.05, false);
  REQUIRE(GpsFake::wait_listening(port, 10s));
  GpsdConfig cfg = config_for(port);
  cfg.backoff_min = cfg.backoff_max = 10'000ms;  // stop() wakes the wait: the test does not sit it out
  GpsdClient client(cfg);
  client.start();
  REQUIRE(wait_for([&] { return client.has_gps(gearpulse::monotonic_ns()); }, 20s));
  fake.kill();
  // Said at once; a client that stayed "connected" through the wait would say so for 10 s. Half of that
  // is room for a sanitized build on a loaded machine to see the connection close.
  CHECK(wait_for([&] { return client.status().state == GpsdState::kConnecting; }, 5s));
  // The error names the gpsd that was lost, as a failed connect does.
  CHECK(client.status().last_error.find(std::to_string(port)) != std::string::npos);
  client.stop();
}
