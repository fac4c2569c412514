#pragma once
// The GPS reports of the last minute or so, so that a hop the tracker thread steps late takes the fix of
// its own time. A thread that keeps pace steps each hop as soon as the capture has given its window, and
// judges GPS then, on the newest report. A thread held back (a loaded machine) drains seconds of audio in
// one turn; judged when it runs, those hops got a fix newer than they are, or GPS already lost or back at
// an outage's edge, and the synthesis depended on how the thread was scheduled. Such a hop, and only such
// a hop, is judged at the moment a thread keeping pace would have stepped it (for_hop()). One writer (the
// gpsd client's thread), any number of readers, no lock and no allocation on either side.
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
  // (about 100 KiB) cover it, and a few seconds of a backlog for a receiver that reports each fix twice. A
  // hop later than the history reaches takes its oldest report (at()).
  static constexpr std::size_t kSize = 1024;

  // The GPS a hop gets, and whether it was late (judged at `due_ns`, not when the thread ran).
  struct ForHop {
    std::optional<GpsReport> fix;
    bool late = false;
  };

  // The writer thread only: `report` is the newest (reports come in order of receive time).
  void record(const GpsReport& report) noexcept {
    const std::uint64_t n = count_.load(std::memory_order_relaxed);
    ring_[n % kSize].publish(report);
    count_.store(n + 1, std::memory_order_release);
  }

  // The newest report received.
  [[nodiscard]] std::optional<GpsReport> latest() const noexcept {
    const std::uint64_t n = count_.load(std::memory_order_acquire);
    if (n == 0) return std::nullopt;
    return ring_[(n - 1) % kSize].read();
  }

  // The report that was the newest at `t_ns` (CLOCK_MONOTONIC): the last one received no later. When `t_ns`
  // is older than every report kept (the history went round: a hop later than the capture ring can hold),
  // the oldest kept, the nearest known state. None before the first report, or when `t_ns` precedes it.
  [[nodiscard]] std::optional<GpsReport> at(std::int64_t t_ns) const noexcept;

  // `report` if it is usable and was received no longer than `timeout_ns` before `t_ns`.
  [[nodiscard]] static std::optional<GpsReport> judged(const std::optional<GpsReport>& report,
                                                       std::int64_t t_ns, std::int64_t timeout_ns) noexcept {
    if (!report || !report->usable() || t_ns - report->rx_ns > timeout_ns) return std::nullopt;
    return report;
  }

  // GPS now: the newest report, judged at `now_ns`.
  [[nodiscard]] std::optional<GpsReport> fresh(std::int64_t now_ns, std::int64_t timeout_ns) const noexcept {
    return judged(latest(), now_ns, timeout_ns);
  }

  // GPS for a hop stepped at `now_ns` that a thread keeping pace steps by `due_ns` (the hop's time and the
  // pipeline's latency). A hop on time (`now_ns` <= `due_ns`) gets GPS now, exactly as fresh(): the code and
  // the moment a hop was always judged at. A hop of a backlog drained late gets the report that was newest
  // at `due_ns`, judged then: what it would have had stepped in pace, whether a newer report came since or
  // none did (a gpsd thread held back by the same load, or gone).
  [[nodiscard]] ForHop for_hop(std::int64_t due_ns, std::int64_t now_ns,
                               std::int64_t timeout_ns) const noexcept {
    if (now_ns <= due_ns) return {fresh(now_ns, timeout_ns), false};
    return {judged(at(due_ns), due_ns, timeout_ns), true};
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
    // Once the ring is full, each report recorded during this loop overwrites the oldest slot with a newer
    // report: it is skipped as received after `t_ns` (and the oldest kept is then the next slot's).
    const GpsReport r = ring_[(n - 1 - i) % kSize].read();
    if (r.rx_ns <= t_ns) return r;
    if (!oldest || r.rx_ns < oldest->rx_ns) oldest = r;
  }
  if (n > kSize) return oldest;
  return std::nullopt;
}

}  // namespace gearpulse
