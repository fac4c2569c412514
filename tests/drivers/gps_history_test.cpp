// GpsHistory: the report newest at a past time, as the tracker thread asks for it at a hop's time.
#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <optional>
#include <thread>

#include "drivers/gps_history.hpp"

using gearpulse::GpsHistory;
using gearpulse::GpsReport;

namespace {

constexpr std::int64_t kSecond = 1'000'000'000;

// A 3D fix at `speed` received at `rx_s` s; a speed below zero reports no fix.
GpsReport report(double rx_s, double speed) {
  GpsReport r;
  r.rx_ns = static_cast<std::int64_t>(rx_s * kSecond);
  r.mode = speed < 0.0 ? 1 : 3;
  if (speed >= 0.0) r.speed = speed;
  return r;
}

}  // namespace

TEST_CASE("gps history: the report newest at a time is the last received no later") {
  GpsHistory h;
  CHECK_FALSE(h.latest());
  CHECK_FALSE(h.at(100 * kSecond));
  h.record(report(10.0, 5.0));
  h.record(report(11.0, 6.0));
  h.record(report(12.0, -1.0));    // GPS lost
  CHECK_FALSE(h.at(9 * kSecond));  // before the first report
  CHECK(h.at(10 * kSecond)->speed == 5.0);
  CHECK(h.at(10 * kSecond + kSecond / 2)->speed == 5.0);
  CHECK(h.at(11 * kSecond)->speed == 6.0);
  CHECK(h.at(12 * kSecond)->mode == 1);
  CHECK(h.latest()->mode == 1);
}

TEST_CASE("gps history: a hop on time gets the newest report judged now, a late hop the report of its time") {
  GpsHistory h;
  const std::int64_t timeout = 3 * kSecond / 2;
  CHECK_FALSE(h.for_hop(10 * kSecond, 10 * kSecond, timeout).fix);
  CHECK_FALSE(h.for_hop(10 * kSecond, 10 * kSecond, timeout).late);
  h.record(report(10.0, 5.0));
  h.record(report(11.0, 6.0));
  // Fresh: the newest report, usable and no older than the timeout now.
  CHECK(h.fresh(12 * kSecond, timeout)->speed == 6.0);
  CHECK_FALSE(h.fresh(13 * kSecond, timeout));
  // Stepped by its due time: on time, judged now as fresh() judges, on the newest report.
  for (const std::int64_t now : {11 * kSecond, 12 * kSecond, 13 * kSecond}) {
    const GpsHistory::ForHop on_time = h.for_hop(13 * kSecond, now, timeout);
    CHECK_FALSE(on_time.late);
    CHECK(on_time.fix.has_value() == h.fresh(now, timeout).has_value());
  }
  // Stepped after its due time with no report since (the gpsd thread held back by the same load, or
  // gone): late, the newest report judged at the due time, not now, when it is stale.
  const GpsHistory::ForHop stalled = h.for_hop(11 * kSecond + kSecond / 2, 13 * kSecond, timeout);
  CHECK(stalled.late);
  REQUIRE(stalled.fix);
  CHECK(stalled.fix->speed == 6.0);
  h.record(report(12.0, -1.0));  // GPS lost
  CHECK_FALSE(h.fresh(12 * kSecond, timeout));
  // A hop due before the loss, stepped after it: the fix of its due time, judged then.
  const GpsHistory::ForHop late = h.for_hop(11 * kSecond + kSecond / 2, 12 * kSecond + kSecond / 10, timeout);
  CHECK(late.late);
  REQUIRE(late.fix);
  CHECK(late.fix->speed == 6.0);
  // Due before any report: none.
  CHECK(h.for_hop(9 * kSecond, 12 * kSecond, timeout).late);
  CHECK_FALSE(h.for_hop(9 * kSecond, 12 * kSecond, timeout).fix);
  // Due 2 s after the last fix, with only its report before: stale then too.
  h.record(report(14.0, 7.0));
  CHECK_FALSE(h.for_hop(13 * kSecond, 14 * kSecond, timeout).fix);
  CHECK(h.for_hop(14 * kSecond, 15 * kSecond, timeout).fix->speed == 7.0);
}

TEST_CASE("gps history: a time older than every report kept gets the oldest kept") {
  GpsHistory h;
  const auto n = static_cast<int>(GpsHistory::kSize) + 10;
  for (int i = 0; i < n; ++i)
    h.record(report(i, i));
  CHECK(h.latest()->speed == n - 1);
  CHECK(h.at(20 * kSecond)->speed == 20.0);
  // Reports 0-9 went round: the nearest known state is the oldest kept.
  CHECK(h.at(3 * kSecond)->speed == 10.0);
  const GpsHistory::ForHop late = h.for_hop(3 * kSecond, n * kSecond, kSecond);
  CHECK(late.late);
  CHECK(late.fix->speed == 10.0);
}

TEST_CASE("gps history: a reader beside the writer never gets a report from after its time") {
  // The gpsd thread records while the tracker thread asks; run under ThreadSanitizer in the test command.
  // The reader asks for the time of a report up to a quarter of the history behind the newest, so that
  // at() scans slots the writer is overwriting; every answer is the report of exactly that time. The
  // writer stays within half the history of the reader's last question (a receiver reports a few times a
  // second, not a history's worth during one question).
  GpsHistory h;
  constexpr int kReports = 20000;
  constexpr int kAhead = static_cast<int>(GpsHistory::kSize / 2);
  const auto rx = [](int i) { return static_cast<std::int64_t>(i) * kSecond / 10; };
  std::atomic<int> recorded{-1};  // index of the newest report recorded (received at rx(i))
  std::atomic<int> asked_for{0};  // index the reader last asked about
  std::thread writer([&] {
    for (int i = 0; i < kReports; ++i) {
      while (i - asked_for.load(std::memory_order_acquire) > kAhead)
        std::this_thread::yield();
      GpsReport r = report(0.0, 10.0);
      r.rx_ns = rx(i);
      h.record(r);
      recorded.store(i, std::memory_order_release);
    }
  });
  int wrong = 0, asked = 0;
  while (recorded.load(std::memory_order_acquire) < kReports - 1) {
    const int i = recorded.load(std::memory_order_acquire);
    if (i < 0) continue;
    asked_for.store(i, std::memory_order_release);
    const int back = std::min(i, asked % (kAhead / 2));
    const std::int64_t t = rx(i - back);
    const std::optional<GpsReport> r = h.at(t);
    ++asked;
    if (!r || r->rx_ns != t) ++wrong;
  }
  writer.join();
  CHECK(asked > 0);
  CHECK(wrong == 0);
}
