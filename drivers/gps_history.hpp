#pragma once
// The GPS reports of the last minute or so, so that a step of the synthesis takes the fix of its own time:
// the tracker thread may step a hop well after the hop's time (it fell behind and drains a backlog of
// audio), and the GPS state at that later moment is not the one the hop saw: the fix may be newer than the
// hop, or lost or back already at an outage's edge. `gearpulse replay` pairs each hop with the fix of its
// time; the daemon asks this history for the same, so what it synthesizes does not depend on when its
// thread ran. One writer (the gpsd client's thread), any number of readers, no lock and no allocation on
// either side.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <optional>

#include "core/published.hpp"
#include "drivers/gps_report.hpp"

namespace gearpulse {

class GpsHistory {
 public:
  // Reports kept: a hop can be late by at most what the capture ring holds (`audio.ring_seconds`, at most
  // 60 s), and a 10 Hz receiver, the fastest gpsd serves a car PC, reports 600 times in that; 1024 slots
  // (about 64 KiB) cover it with room for receivers that report a fix as several sentences.
  static constexpr std::size_t kSize = 1024;

  // The writer thread only: `report` is the newest (reports come in order of receive time).
  void record(const GpsReport& report) noexcept {
    const std::uint64_t n = count_.load(std::memory_order_relaxed);
    ring_[n % kSize].publish(report);
    count_.store(n + 1, std::memory_order_release);
  }

  // The newest report received.
  [[nodiscard]] std::optional<GpsReport> newest() const noexcept {
    const std::uint64_t n = count_.load(std::memory_order_acquire);
    if (n == 0) return std::nullopt;
    return ring_[(n - 1) % kSize].read();
  }

  // The report that was the newest at `t_ns` (CLOCK_MONOTONIC): the last one received no later. When `t_ns`
  // is older than every report kept (the history went round: a hop later than the capture ring can hold),
  // the oldest kept, the nearest known state; fresh() then judges it as if received at `t_ns`. None before
  // the first report, or when `t_ns` precedes it.
  [[nodiscard]] std::optional<GpsReport> at(std::int64_t t_ns) const noexcept;

  // The report newest at `t_ns` if it is usable and was received no longer than `timeout_ns` before.
  [[nodiscard]] std::optional<GpsReport> fresh(std::int64_t t_ns, std::int64_t timeout_ns) const noexcept {
    const std::optional<GpsReport> then = at(t_ns);
    if (!then || !then->usable() || t_ns - std::min(then->rx_ns, t_ns) > timeout_ns) return std::nullopt;
    return then;
  }

 private:
  std::array<Published<GpsReport>, kSize> ring_;
  std::atomic<std::uint64_t> count_{0};  // reports recorded; the newest is in slot (count_ - 1) % kSize
};

inline std::optional<GpsReport> GpsHistory::at(std::int64_t t_ns) const noexcept {
  const std::uint64_t n = count_.load(std::memory_order_acquire);
  const std::uint64_t kept = n < kSize ? n : kSize;
  std::optional<GpsReport> oldest;
  for (std::uint64_t i = 0; i < kept; ++i) {
    // A writer that went round the whole ring during this loop (kSize reports in microseconds) could
    // leave a newer report in a slot: it is skipped as received after `t_ns`.
    const GpsReport r = ring_[(n - 1 - i) % kSize].read();
    if (r.rx_ns <= t_ns) return r;
    if (!oldest || r.rx_ns < oldest->rx_ns) oldest = r;
  }
  if (n > kSize) return oldest;
  return std::nullopt;
}

}  // namespace gearpulse
