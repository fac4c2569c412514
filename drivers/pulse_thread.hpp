#pragma once
// The real-time pulse thread: sleeps to each edge the PulseScheduler computes and calls the output's
// rise()/fall(). The target speed comes from another thread through an atomic; set_speed() signals a
// WakeEvent (an eventfd) when the speed changes, and the thread waits on it until the next edge, so it wakes
// for an edge or a new speed (a start from standstill is taken up at once), and at least every heartbeat
// to show the watchdog it turns. The loop never allocates, locks, logs or throws.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <span>

#include "core/pulse_scheduler.hpp"
#include "drivers/device_thread.hpp"
#include "drivers/pulse_output.hpp"
#include "drivers/wake_event.hpp"

namespace gearpulse {

struct PulseThreadConfig {
  PulseConfig pulse;
  // Longest sleep without an edge or a new speed: the period of the heartbeat the daemon's watchdog judges
  // (daemon/watchdog.hpp, kStallNs = 5 s). A twentieth of that limit: a thread at standstill wakes four
  // times a second, and only a wait stretched twenty-fold past its time reads as hung.
  std::chrono::milliseconds heartbeat_period{250};
  bool realtime = false;  // request SCHED_FIFO (failure is reported, not fatal)
  int rt_priority = 80;
  bool lock_memory = false;  // mlockall, as make_realtime does (failure reported)
};

// One rising edge as planned and as done, for benches and tests.
struct RiseRecord {
  std::int64_t scheduled_ns = 0;  // the scheduler's edge time
  std::int64_t written_ns = 0;    // CLOCK_MONOTONIC when output.rise() returned
};

struct PulseThreadStatus {
  std::uint64_t pulses = 0;       // rising edges emitted
  std::uint64_t late_edges = 0;   // edges emitted more than 1 ms after their scheduled time
  std::int64_t max_late_ns = 0;   // worst lateness seen
  std::uint64_t discarded = 0;    // pulses owed beyond the scheduler's bound, dropped (PulseScheduler)
  bool realtime_ok = false;       // SCHED_FIFO granted
  bool memory_locked = false;     // mlockall succeeded
  bool realtime_refused = false;  // SCHED_FIFO or the memory lock asked for was refused
  bool running = false;
  std::int64_t heartbeat_ns = 0;  // CLOCK_MONOTONIC of the last turn of its loop (one a heartbeat at least)
  // Turns of its loop: one per wake-up (for edges due, a new speed, a heartbeat or stop()). At a constant
  // speed about one per edge: the thread does not wake to look at the speed.
  std::uint64_t turns = 0;
};

class PulseThread {
 public:
  // `output` is borrowed and must outlive the thread. `rise_log` (optional, borrowed) receives every
  // rising edge, in order, until it is full: for benches and tests.
  // Throws std::system_error if no eventfd can be had.
  PulseThread(PulseOutput& output, PulseThreadConfig config, std::span<RiseRecord> rise_log = {});
  ~PulseThread();  // stop()
  PulseThread(const PulseThread&) = delete;
  PulseThread& operator=(const PulseThread&) = delete;

  void start();  // throws std::invalid_argument for a bad PulseConfig, std::system_error if no thread
  void stop();   // joins; the output is left low

  // Lock-free, callable from any thread at any time. NaN or negative means standstill. Wakes the thread
  // (one eventfd write) only when the speed it would apply changes: a hop's speed, ten times a second.
  void set_speed(double speed_mps) noexcept;
  [[nodiscard]] double target_speed() const noexcept { return target_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t pulses() const noexcept { return pulses_.load(std::memory_order_acquire); }
  [[nodiscard]] std::size_t logged() const noexcept { return logged_.load(std::memory_order_acquire); }
  [[nodiscard]] PulseThreadStatus status() const noexcept;

 private:
  void run(std::int64_t t0_ns) noexcept;

  PulseOutput& output_;
  const PulseThreadConfig config_;
  std::span<RiseRecord> rise_log_;
  std::atomic<std::int64_t> heartbeat_ns_{0};
  std::atomic<double> target_{0.0};
  std::atomic<std::uint64_t> pulses_{0};
  std::atomic<std::uint64_t> late_edges_{0};
  std::atomic<std::int64_t> max_late_ns_{0};
  std::atomic<std::uint64_t> discarded_{0};
  std::atomic<std::size_t> logged_{0};
  std::atomic<std::uint64_t> turns_{0};
  WakeEvent wake_;       // set_speed() and stop() signal it, the thread waits on it
  DeviceThread thread_;  // last: stopped before the members it uses go
};

}  // namespace gearpulse
