// The systemd watchdog is fed only while every pipeline thread beats: the decision on simulated
// heartbeats (no sleeping), then the live pipeline looked at from the future.
#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/model_store.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/training_store.hpp"
#include "daemon/watchdog.hpp"
#include "drivers/clock.hpp"
#include "tests/test_util.hpp"

using gearpulse::daemon::GpsState;
using gearpulse::daemon::kStallNs;
using gearpulse::daemon::stalled_threads;
using gearpulse::daemon::ThreadBeat;
using gearpulse::daemon::WatchdogGate;
using gearpulse::test::TempDir;
using gearpulse::test::wait_for;
using namespace std::chrono_literals;

namespace {

constexpr std::int64_t kSecond = 1'000'000'000;

bool contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

}  // namespace

TEST_CASE("watchdog: a thread is hung once its heartbeat is older than the stall limit or it ended") {
  const std::int64_t now = 100 * kSecond;
  const std::vector<ThreadBeat> beats = {
      {"tracker", now - kSecond},   // beat a second ago: alive
      {"gps", now - kStallNs - 1},  // just past the limit: hung
      {"pulse", now, true},         // beat now but its thread has returned: hung
      {"spare", now - kStallNs},    // exactly at the limit: still alive
      {"future", now + kSecond},    // a beat stamped after `now` (read late): alive
  };
  CHECK(stalled_threads(beats, now) == std::vector<std::string>{"gps", "pulse"});
  CHECK(stalled_threads(beats, now, 500'000'000) ==
        std::vector<std::string>{"tracker", "gps", "pulse", "spare"});
  CHECK(stalled_threads({}, now).empty());
}

TEST_CASE("watchdog: a stalled thread withholds WATCHDOG=1 until it beats again") {
  int pings = 0;
  WatchdogGate gate([&] { ++pings; });
  // Simulated time in 0.5 s ticks of the main loop. The tracker beats at every tick. The GPS thread
  // first backs off against an absent gpsd, beating every 0.5 s of its wait (alive); from 20 s it
  // hangs; at 40 s it beats again.
  std::int64_t tracker_beat = 0, gps_beat = 0;
  int logged = 0;
  std::vector<int> fed_at, withheld_at;
  for (std::int64_t t = 0; t <= 50 * kSecond; t += kSecond / 2) {
    tracker_beat = t;
    if (t < 20 * kSecond || t >= 40 * kSecond) gps_beat = t;
    const std::vector<ThreadBeat> beats = {{"tracker", tracker_beat}, {"gps", gps_beat}};
    const int before = pings;
    logged += gate.tick(stalled_threads(beats, t)) ? 1 : 0;
    (pings > before ? fed_at : withheld_at).push_back(static_cast<int>(t / (kSecond / 2)));
  }
  // Fed through the backoff, withheld from the first tick more than 5 s after the last beat until the
  // thread beats again, and the hang logged once, not at every tick.
  REQUIRE_FALSE(withheld_at.empty());
  CHECK(withheld_at.front() == 50);  // 25 s: the first tick more than kStallNs after the beat at 19.5 s
  CHECK(withheld_at.back() == 79);   // 39.5 s: the last tick before the thread beats again
  CHECK(withheld_at.size() == 30);
  CHECK(gate.withheld() == 30);
  CHECK(gate.fed() == static_cast<std::uint64_t>(pings));
  CHECK(fed_at.size() + withheld_at.size() == 101);
  CHECK(logged == 1);
}

TEST_CASE("watchdog: a hang is logged again when another thread joins it or when it comes back") {
  // One log line per hang, not per tick: but a second thread hanging, or a thread that recovered and
  // hangs again an hour later, is news the user needs to find in the log.
  int pings = 0;
  WatchdogGate gate([&] { ++pings; });
  const std::vector<std::string> none, gps{"gps"}, gps_pulse{"gps", "pulse"}, pulse{"pulse"};
  CHECK_FALSE(gate.tick(none));
  CHECK(gate.tick(gps));
  CHECK_FALSE(gate.tick(gps));
  CHECK(gate.tick(gps_pulse));  // the pulse thread hangs too
  CHECK_FALSE(gate.tick(gps_pulse));
  CHECK(gate.tick(pulse));  // the GPS thread is back, the pulse thread is not
  CHECK_FALSE(gate.tick(none));
  CHECK(pings == 2);
  CHECK(gate.tick(pulse));  // the same thread hangs again after recovering
  CHECK_FALSE(gate.tick(pulse));
  CHECK(gate.withheld() == 7);
  CHECK(gate.fed() == 2);
}

TEST_CASE("watchdog: the pipeline watches the GPS thread and an absent gpsd is not a stall") {
  TempDir dir;
  gearpulse::daemon::Config config;
  config.audio.device = "gearpulse_test_no_such_pcm";
  config.gps.port = static_cast<unsigned>(gearpulse::test::free_port());  // nobody listens: gpsd absent
  config.output.kind = gearpulse::daemon::OutputKind::kNone;
  config.model.state_dir = dir.path().string();
  config.log.level = "off";
  gearpulse::daemon::ModelHolder model;
  gearpulse::daemon::TrainingStore store(3600.0, 1000);
  gearpulse::daemon::Pipeline pipeline(config, model, store);
  pipeline.start();
  // The GPS thread keeps failing to connect and backs off meanwhile.
  REQUIRE(wait_for([&] { return !pipeline.snapshot().gps_error.empty(); }, 20s));
  const std::int64_t now = gearpulse::monotonic_ns();
  const auto live = pipeline.snapshot(now);
  CHECK(live.gps_state == GpsState::kDisconnected);
  CHECK(live.stalled.empty());
  // Seen from beyond the stall limit every thread's last beat is stale, the GPS thread's included: it
  // is one of the threads the watchdog waits for.
  const auto later = pipeline.snapshot(now + kStallNs + 2 * kSecond);
  CHECK(contains(later.stalled, "gps"));
  CHECK(contains(later.stalled, "tracker"));
  CHECK(contains(later.stalled, "pulse"));
  pipeline.stop();
}
