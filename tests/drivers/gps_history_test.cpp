// GpsHistory: the report newest at a past time, as the tracker thread asks for it at a hop's time.
#include <catch2/catch.hpp>

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
  CHECK_FALSE(h.newest());
  CHECK_FALSE(h.at(100 * kSecond));
  h.record(report(10.0, 5.0));
  h.record(report(11.0, 6.0));
  h.record(report(12.0, -1.0));    // GPS lost
  CHECK_FALSE(h.at(9 * kSecond));  // before the first report
  CHECK(h.at(10 * kSecond)->speed == 5.0);
  CHECK(h.at(10 * kSecond + kSecond / 2)->speed == 5.0);
  CHECK(h.at(11 * kSecond)->speed == 6.0);
  CHECK(h.at(12 * kSecond)->mode == 1);
  CHECK(h.newest()->mode == 1);
  // Fresh: usable and no older than the timeout at that time.
  const std::int64_t timeout = 3 * kSecond / 2;
  CHECK(h.fresh(11 * kSecond + kSecond / 2, timeout)->speed == 6.0);  // a hop before the loss had GPS
  CHECK_FALSE(h.fresh(12 * kSecond, timeout));                        // lost
  CHECK_FALSE(h.fresh(9 * kSecond, timeout));
}

TEST_CASE("gps history: a time older than every report kept gets the oldest kept") {
  GpsHistory h;
  const auto n = static_cast<int>(GpsHistory::kSize) + 10;
  for (int i = 0; i < n; ++i)
    h.record(report(i, i));
  CHECK(h.newest()->speed == n - 1);
  CHECK(h.at(20 * kSecond)->speed == 20.0);
  // Reports 0-9 went round: the nearest known state is the oldest kept.
  CHECK(h.at(3 * kSecond)->speed == 10.0);
  CHECK(h.fresh(3 * kSecond, kSecond)->speed == 10.0);
}

TEST_CASE("gps history: a reader beside the writer never gets a report from after its time") {
  // The gpsd thread records while the tracker thread asks; run under ThreadSanitizer in the test command.
  // Every report the reader gets was received no later than the time it asked for, and the answers for
  // a time that only grows never go back.
  GpsHistory h;
  constexpr int kReports = 20000;
  std::atomic<std::int64_t> recorded{-1};  // rx_ns of the newest report recorded
  std::thread writer([&] {
    for (int i = 0; i < kReports; ++i) {
      h.record(report(i * 0.1, 10.0));
      recorded.store(static_cast<std::int64_t>(i * 0.1 * kSecond), std::memory_order_release);
    }
  });
  int wrong = 0, backwards = 0, asked = 0;
  std::int64_t last = -1;
  while (recorded.load(std::memory_order_acquire) <
         static_cast<std::int64_t>((kReports - 1) * 0.1 * kSecond)) {
    const std::int64_t t = recorded.load(std::memory_order_acquire);
    if (t < 0) continue;
    const std::optional<GpsReport> r = h.at(t);
    ++asked;
    if (!r || r->rx_ns > t)
      ++wrong;
    else if (r->rx_ns < last)
      ++backwards;
    else
      last = r->rx_ns;
  }
  writer.join();
  CHECK(asked > 0);
  CHECK(wrong == 0);
  CHECK(backwards == 0);
}
