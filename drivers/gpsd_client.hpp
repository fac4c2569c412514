#pragma once
// GPS speed from gpsd through libgps (JSON watch). A thread connects, drains every batch of buffered
// reports so only the newest position/velocity report counts, and publishes it; when gpsd is absent,
// dies or restarts it reconnects with exponential backoff and says so in its status. Garbage from the
// socket is counted and skipped; it never ends the thread.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "core/gps_speed_gate.hpp"
#include "drivers/gps_history.hpp"
#include "drivers/gps_report.hpp"

namespace gearpulse {

struct GpsdConfig {
  std::string host = "127.0.0.1";
  std::string port = "2947";
  std::chrono::milliseconds no_fix_timeout{1500};  // no usable report for longer: "no GPS"
  std::chrono::milliseconds backoff_min{200};      // first reconnect delay, doubled up to backoff_max
  std::chrono::milliseconds backoff_max{5000};
};

enum class GpsdState : std::uint8_t { kStopped, kConnecting, kConnected };

struct GpsdStatus {
  GpsdState state = GpsdState::kStopped;
  std::uint64_t reports = 0;     // position/velocity reports published
  std::uint64_t superseded = 0;  // reports drained and replaced by a newer one in the same batch
  std::uint64_t connects = 0;    // successful connections (1 = first, more = reconnects)
  std::uint64_t failures = 0;    // failed connection attempts and lost connections
  std::uint64_t bad_reads = 0;   // reads libgps could not parse
  // Reports whose speed no car reaches, or reaches that fast (GpsSpeedGate): published without a speed,
  // so they count as no fix; the last such speed (m/s).
  std::uint64_t implausible = 0;
  double last_implausible = 0.0;
  // Reports whose fix gpsd gives as dead-reckoned, time-only or simulated: published without a speed.
  std::uint64_t unmeasured = 0;
  // Reports of another device than the one followed, while that one gives fixes: skipped.
  std::uint64_t other_device = 0;
  std::string last_error;  // empty if none yet
};

[[nodiscard]] const char* to_string(GpsdState state) noexcept;

class GpsdClient final {
 public:
  using Callback = std::function<void(const GpsReport&)>;
  // `on_report` (optional) runs on the client thread for every published report; keep it short.
  explicit GpsdClient(GpsdConfig config, Callback on_report = {});
  ~GpsdClient();  // stop()
  GpsdClient(const GpsdClient&) = delete;
  GpsdClient& operator=(const GpsdClient&) = delete;

  void start();  // starts the thread (idempotent); never throws for an absent gpsd: it keeps trying
  void stop();   // joins the thread within ~100 ms

  // The newest report, if any arrived yet (GpsHistory::latest). Lock-free.
  [[nodiscard]] std::optional<GpsReport> latest() const noexcept { return history_.latest(); }
  // The newest report if it is usable and was received no longer ago than the no-fix timeout (its speed
  // and its freshness judged on that one report). Lock-free as latest().
  [[nodiscard]] std::optional<GpsReport> fresh(std::int64_t now_ns) const noexcept {
    return history_.fresh(now_ns, timeout_ns());
  }
  [[nodiscard]] bool has_gps(std::int64_t now_ns) const noexcept { return fresh(now_ns).has_value(); }
  // GPS for a hop stepped at `now_ns` that a thread keeping pace steps by `due_ns` (GpsHistory::for_hop):
  // fresh(now_ns) while `now_ns` <= `due_ns`, else the report newest at `due_ns`, judged then.
  [[nodiscard]] GpsHistory::ForHop for_hop(std::int64_t due_ns, std::int64_t now_ns) const noexcept {
    return history_.for_hop(due_ns, now_ns, timeout_ns());
  }
  [[nodiscard]] GpsdStatus status() const;  // under the lock: for status queries, not a real-time path
  // Proof of life for a watchdog: CLOCK_MONOTONIC of the thread's last sign of life. It beats on every
  // turn of its loop, at least every 100 ms while connected and every kBeatNs while backing off, so an
  // absent gpsd is not a hung thread. Inside gps_open() it counts as alive: a connect to a host that
  // does not answer blocks for as long as the kernel retries (about two minutes), a bounded wait.
  // 0 before start().
  [[nodiscard]] std::int64_t heartbeat_ns() const noexcept;
  static constexpr std::int64_t kBeatNs = 500'000'000;
  [[nodiscard]] const GpsdConfig& config() const noexcept { return config_; }

 private:
  void run();
  bool wait_backoff(std::chrono::milliseconds delay);  // false if stop was requested; beats meanwhile
  void beat() noexcept;
  void set_error(std::string message, bool connection_lost);
  [[nodiscard]] std::int64_t timeout_ns() const noexcept {
    return std::chrono::nanoseconds(config_.no_fix_timeout).count();
  }

  const GpsdConfig config_;
  const Callback on_report_;
  std::thread thread_;
  mutable std::mutex mutex_;  // stop_requested_ and status_; never taken by latest() or fresh()
  std::condition_variable wake_;
  bool stop_requested_ = false;
  std::atomic<std::int64_t> beat_ns_{0};
  std::atomic<bool> connecting_{false};
  GpsHistory history_;  // written by the client thread only
  GpsdStatus status_;
  GpsSpeedGate gate_;  // client thread only
  // The device followed (client thread only): the one of the last usable fix, and when it came.
  std::string device_;
  std::int64_t device_fix_ns_ = 0;
};

}  // namespace gearpulse
