#pragma once
// When gearpulsed feeds the systemd watchdog. Every pipeline thread shows it is alive by a heartbeat,
// the CLOCK_MONOTONIC time of the last turn of its loop. A thread whose heartbeat is older than the
// stall limit, or that has ended while it should run, is hung; while any thread is hung WATCHDOG=1 is
// withheld, so systemd restarts the daemon after WatchdogSec. A thread that waits on purpose (a
// reconnect backoff while gpsd is absent, a retry while the sound card is missing) keeps beating:
// waiting is alive, only a thread that stopped turning is hung.
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

namespace gearpulse::daemon {

// A heartbeat older than this is a hung thread. Well above every loop's longest regular wait (the
// GPS backoff beats every 0.5 s, the tracker and the pulse thread every 250 ms at least),
// and below any sensible WatchdogSec.
inline constexpr std::int64_t kStallNs = 5'000'000'000;

struct ThreadBeat {
  std::string name;      // "tracker", "gps", "pulse"
  std::int64_t last_ns;  // CLOCK_MONOTONIC of its last beat
  bool ended = false;    // the thread has returned although it should be running
};

// Names of the threads hung at `now_ns`, in the order given.
[[nodiscard]] std::vector<std::string> stalled_threads(std::span<const ThreadBeat> beats, std::int64_t now_ns,
                                                       std::int64_t stall_ns = kStallNs);

// Feeds the watchdog once per tick of the main loop, only while no thread is hung.
class WatchdogGate {
 public:
  explicit WatchdogGate(std::function<void()> feed) : feed_(std::move(feed)) {}

  // `stalled`: the threads hung at this tick. Feeds the watchdog if there are none. Returns true when
  // the set of hung threads has just changed to a non-empty one (worth one log line, not one a tick).
  bool tick(const std::vector<std::string>& stalled);
  [[nodiscard]] std::uint64_t fed() const noexcept { return fed_; }
  [[nodiscard]] std::uint64_t withheld() const noexcept { return withheld_; }

 private:
  std::function<void()> feed_;
  std::vector<std::string> last_stalled_;
  std::uint64_t fed_ = 0;
  std::uint64_t withheld_ = 0;
};

}  // namespace gearpulse::daemon
