// GpsdClient against a gpsd that is absent, misbehaves or goes away: a fake gpsd on a loopback socket the
// test plays itself, the reconnect delays and the heartbeat through them. gpsd_client_test.cpp has the
// client against a real gpsd (gpsfake).
#include <catch2/catch.hpp>

#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <string>
#include <thread>

#include "drivers/clock.hpp"
#include "drivers/gpsd_client.hpp"
#include "drivers/unique_fd.hpp"
#include "tests/drivers/gpsd_endpoints.hpp"
#include "tests/test_util.hpp"

using namespace std::chrono_literals;
using gearpulse::GpsdClient;
using gearpulse::GpsdConfig;
using gearpulse::GpsdState;
using gearpulse::UniqueFd;
using gearpulse::test::config_for;
using gearpulse::test::FakeGpsd;
using gearpulse::test::Recorder;
using gearpulse::test::wait_for;

TEST_CASE("gpsd: garbage from the socket is skipped and never ends the client") {
  // A fake gpsd: answers every connection with junk, a malformed TPV, binary noise, then one good TPV.
  const FakeGpsd gpsd([](int fd, const std::atomic<bool>&) {
    std::string junk = "this is not json\n{\"class\":\"TPV\",\"mode\":\"three\",\"speed\":[1,2]}\n";
    junk += std::string("\x01\xff\xfe{{{{\"\n", 9);
    junk += "{\"class\":\"TPV\",\"speed\":1e999999,\"mode\":3}\n";
    junk +=
        "{\"class\":\"TPV\",\"device\":\"x\",\"mode\":3,\"time\":\"2026-01-15T12:00:00.000Z\",\"speed\":4."
        "125}\n";
    (void)!::write(fd, junk.data(), junk.size());
    std::this_thread::sleep_for(100ms);
  });
  GpsdClient client(config_for(gpsd.port()));
  client.start();
  const bool got = wait_for(
      [&] {
        const auto r = client.latest();
        return r && r->usable() && std::fabs(r->speed - 4.125) < 1e-9;
      },
      20s);
  const auto st = client.status();
  CHECK(got);
  CHECK(st.connects >= 1);
  INFO("bad reads " << st.bad_reads << ", failures " << st.failures << ", last error " << st.last_error);
  CHECK(st.bad_reads + st.failures >= 1);
}

TEST_CASE("gpsd: a gpsd that greets and hangs up is retried with a growing delay, not hammered") {
  // A broken gpsd (or something else on its port): every connection gets gpsd's banner and is closed.
  std::atomic<int> accepted{0};
  const FakeGpsd gpsd([&](int fd, const std::atomic<bool>&) {  // closed as each call returns
    ++accepted;
    const std::string banner =
        "{\"class\":\"VERSION\",\"release\":\"3.22\",\"rev\":\"3.22\",\"proto_major\":3,\"proto_minor\":14}"
        "\n";
    (void)!::write(fd, banner.data(), banner.size());
    std::this_thread::sleep_for(20ms);
  });
  GpsdConfig cfg = config_for(gpsd.port());  // backoff 50 ms doubling to 400 ms
  GpsdClient client(cfg);
  client.start();
  std::this_thread::sleep_for(3s);
  const int in_3s = accepted.load();
  // That it retries at all is waited for: a loaded machine may be slow to make the first few attempts.
  const bool retried = wait_for([&] { return accepted.load() >= 3; }, 20s);
  client.stop();
  // With the delay reset by the banner the client would reconnect every 50 ms plus the 20 ms the server
  // holds the line (about 40 times in 3 s); growing to 400 ms it connects about 10 times. A slow machine
  // only makes fewer attempts: the upper bound holds whatever the load.
  INFO("connections accepted in 3 s: " << in_3s);
  CHECK(retried);
  CHECK(in_3s <= 16);
}

TEST_CASE("gpsd: the heartbeat goes on through a reconnect backoff while gpsd is absent") {
  GpsdConfig cfg = config_for(gearpulse::test::free_port());
  cfg.backoff_min = cfg.backoff_max = 5000ms;  // one long wait after the first failed attempt
  GpsdClient client(cfg);
  CHECK(client.heartbeat_ns() == 0);  // not started
  client.start();
  REQUIRE(wait_for([&] { return client.status().failures >= 1; }, 10s));
  const std::int64_t h0 = client.heartbeat_ns();
  // It beats while it waits, well before the next attempt: waiting for gpsd is alive, not hung.
  REQUIRE(wait_for([&] { return client.heartbeat_ns() > h0; }, 10s));
  CHECK(client.status().failures == 1);
  CHECK(client.status().state == GpsdState::kConnecting);
  client.stop();  // wakes the backoff at once
  CHECK(client.status().state == GpsdState::kStopped);
}

TEST_CASE("gpsd: an absent gpsd is retried with a growing delay, not hammered") {
  GpsdClient client(config_for(gearpulse::test::free_port()));  // nobody listens; 50 ms doubling to 400 ms
  client.start();
  std::this_thread::sleep_for(2s);
  const auto st = client.status();
  // That it retries at all is waited for: a loaded machine may be slow to make the first few attempts.
  const bool retried = wait_for([&] { return client.status().failures >= 3; }, 20s);
  client.stop();
  // At a fixed 50 ms it would try about 40 times in 2 s; growing to 400 ms, about 8. A slow machine only
  // makes fewer attempts: the upper bound holds whatever the load.
  INFO("failed attempts in 2 s: " << st.failures);
  CHECK(retried);
  CHECK(st.failures <= 12);
}

// The delay grown while gpsd was absent is for an absent gpsd: once one has delivered a position report,
// losing it is retried at once, so a gpsd restart costs the pulses a moment of GPS, not the longest delay.
TEST_CASE("gpsd: after a working connection a lost one is retried at the shortest delay") {
  // Bound but not listening: connections are refused until the test listens.
  const auto [listener, port] = gearpulse::test::loopback_bound();
  GpsdConfig cfg = config_for(port);
  cfg.backoff_max = 6400ms;
  GpsdClient client(cfg);
  client.start();
  // Six refusals: the delay has grown to 3.2 s.
  REQUIRE(wait_for([&] { return client.status().failures >= 6; }, 20s));
  REQUIRE(::listen(listener.get(), 4) == 0);
  UniqueFd first(::accept(listener.get(), nullptr, nullptr));
  REQUIRE(first);
  const std::string tpv =
      "{\"class\":\"TPV\",\"device\":\"x\",\"mode\":3,\"time\":\"2026-01-15T12:00:00.000Z\",\"speed\":6.5}\n";
  (void)!::write(first.get(), tpv.data(), tpv.size());
  REQUIRE(wait_for([&] { return client.latest().has_value(); }, 20s));
  const auto lost_at = std::chrono::steady_clock::now();
  first.reset();  // gpsd goes away
  const UniqueFd second(::accept(listener.get(), nullptr, nullptr));
  const auto waited = std::chrono::steady_clock::now() - lost_at;
  REQUIRE(second);
  client.stop();
  INFO("reconnected after " << std::chrono::duration_cast<std::chrono::milliseconds>(waited).count()
                            << " ms");
  // At the shortest delay it is back 50 ms after the loss; at the grown one, 3.2 s or more. Between the
  // two, 2 s leaves a sanitized build on a loaded machine forty times the 50 ms.
  CHECK(waited < 2s);
}

namespace {
// Writes `line` to a fake gpsd's client, then waits: a report each, not one batch.
void send_line(int fd, const std::string& line) {
  (void)!::write(fd, line.data(), line.size());
  std::this_thread::sleep_for(50ms);
}
}  // namespace

// A receiver dead-reckoning through a tunnel (NMEA's 'E' mode indicator; gpsd's status 5) reports a 3D fix
// and a speed it extrapolated, not measured: taken as no speed, and counted. GNSS with dead reckoning
// (status 6) and a fix without a status are measured.
TEST_CASE("gpsd: a dead-reckoned fix carries no speed, a measured one after it does") {
  const FakeGpsd gpsd([](int fd, const std::atomic<bool>& done) {
    const auto tpv = [&](int second, const std::string& status, double speed) {
      send_line(fd, "{\"class\":\"TPV\",\"device\":\"x\"" + status +
                        ",\"mode\":3,\"time\":\"2026-01-15T12:00:0" + std::to_string(second) +
                        ".000Z\",\"speed\":" + std::to_string(speed) + "}\n");
    };
    for (int i = 0; i < 4; ++i)
      tpv(i, ",\"status\":5", 10.0);
    tpv(4, ",\"status\":6", 11.0);
    tpv(5, "", 12.0);
    while (!done)
      std::this_thread::sleep_for(10ms);
  });
  Recorder rec;
  GpsdClient client(config_for(gpsd.port()), rec.callback());
  client.start();
  REQUIRE(wait_for(
      [&] {
        const auto r = client.latest();
        return r && r->usable() && std::fabs(r->speed - 12.0) < 1e-9;
      },
      20s));
  client.stop();
  std::size_t dead_reckoned = 0;
  for (const gearpulse::GpsReport& r : rec.snapshot()) {
    INFO("fix time " << r.fix_time << ", speed " << r.speed);
    CHECK(r.mode == 3);
    if (r.usable()) {
      CHECK((std::fabs(r.speed - 11.0) < 1e-9 || std::fabs(r.speed - 12.0) < 1e-9));
    } else {
      ++dead_reckoned;
    }
  }
  CHECK(dead_reckoned >= 1);  // reports that come in one read are one report, the newest
  CHECK(client.status().unmeasured == dead_reckoned);
}

// gpsd serves every device it has: a modem's NMEA port without a fix beside the receiver made every other
// report "no fix", and GPS flapped. The device of the last usable fix is followed; another counts once
// that one has given no usable fix for the no-fix timeout.
TEST_CASE("gpsd: a second device without a fix does not hide the first one's fixes") {
  std::atomic<bool> first_gone{false};
  const FakeGpsd gpsd([&](int fd, const std::atomic<bool>& done) {
    for (int i = 0; !done && !first_gone; ++i) {
      send_line(fd, "{\"class\":\"TPV\",\"device\":\"/dev/gps\",\"mode\":3,\"time\":\"2026-01-15T12:00:" +
                        std::to_string(10 + i % 40) + ".000Z\",\"speed\":10.0}\n");
      send_line(fd, "{\"class\":\"TPV\",\"device\":\"/dev/modem\",\"mode\":1}\n");
    }
    // The receiver goes quiet; the modem's port gets a fix of its own.
    for (int i = 0; !done; ++i)
      send_line(fd, "{\"class\":\"TPV\",\"device\":\"/dev/modem\",\"mode\":3,\"time\":\"2026-01-15T12:01:" +
                        std::to_string(10 + i % 40) + ".000Z\",\"speed\":20.0}\n");
  });
  Recorder rec;
  GpsdClient client(config_for(gpsd.port()), rec.callback());
  client.start();
  REQUIRE(wait_for([&] { return rec.size() >= 20 && client.status().other_device >= 10; }, 20s));
  for (const gearpulse::GpsReport& r : rec.snapshot()) {
    CHECK(r.usable());
    CHECK(r.speed == 10.0);
  }
  first_gone = true;
  CHECK(wait_for(
      [&] {
        const auto r = client.latest();
        return r && r->usable() && r->speed == 20.0;
      },
      20s));
}
