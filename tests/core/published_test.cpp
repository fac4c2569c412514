#include <catch2/catch.hpp>

#include <atomic>
#include <cstdint>
#include <optional>
#include <thread>
#include <vector>

#include "core/published.hpp"
#include "drivers/gps_report.hpp"

using gearpulse::GpsReport;
using gearpulse::Published;

namespace {

#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
constexpr std::int64_t kReports = 50'000;  // sanitizers are slow; the interleavings still get exercised
#else
constexpr std::int64_t kReports = 1'000'000;
#endif

// The n-th report: every field follows from n, so a report put together from two writes shows.
GpsReport report(std::int64_t n) {
  GpsReport r;
  r.rx_ns = n;
  r.speed = 0.5 * static_cast<double>(n);
  r.eps = -static_cast<double>(n);
  r.mode = static_cast<int>(n % 4);
  r.fix_time = static_cast<double>(n) + 0.25;
  return r;
}

bool whole(const GpsReport& r) {
  const GpsReport expected = report(r.rx_ns);
  return r.speed == expected.speed && r.eps == expected.eps && r.mode == expected.mode &&
         r.fix_time == expected.fix_time;
}

}  // namespace

TEST_CASE("published: a reader gets the initial value, then the value of the last publish") {
  Published<std::optional<GpsReport>> latest;
  CHECK_FALSE(latest.read().has_value());
  latest.publish(report(7));
  REQUIRE(latest.read().has_value());
  CHECK(latest.read()->rx_ns == 7);
  CHECK(whole(*latest.read()));
  latest.publish(report(8));
  latest.publish(std::nullopt);
  CHECK_FALSE(latest.read().has_value());
  Published<GpsReport> initial(report(3));
  CHECK(initial.read().rx_ns == 3);
}

// The gpsd client thread publishing as fast as it can while real-time readers poll: every read is one
// whole report, never older than one read before it, and the last read after the writer is done is its
// last report. Run under ThreadSanitizer by scripts/test.sh.
TEST_CASE("published: readers on other threads see whole reports, in order, while the writer publishes") {
  Published<std::optional<GpsReport>> latest;
  std::atomic<bool> done{false};
  std::atomic<std::int64_t> torn{0}, backwards{0}, reads{0};
  std::atomic<int> started{0};  // readers that have read once: the writer waits for both
  auto reader = [&] {
    std::int64_t last = -1, n = 0;
    do {
      const std::optional<GpsReport> r = latest.read();
      if (++n == 1) started.fetch_add(1);
      if (!r) continue;
      if (!whole(*r)) torn.fetch_add(1);
      if (r->rx_ns < last) backwards.fetch_add(1);
      last = r->rx_ns;
    } while (!done.load(std::memory_order_acquire));
    reads.fetch_add(n);
  };
  std::vector<std::thread> readers;
  for (int i = 0; i < 2; ++i)
    readers.emplace_back(reader);
  std::thread writer([&] {
    // A sanitized build on a loaded machine may start the readers late: publish while they read.
    while (started.load() < 2)
      std::this_thread::yield();
    for (std::int64_t n = 0; n < kReports; ++n)
      latest.publish(report(n));
    done.store(true, std::memory_order_release);
  });
  writer.join();
  for (std::thread& t : readers)
    t.join();
  CHECK(torn.load() == 0);
  CHECK(backwards.load() == 0);
  CHECK(reads.load() > 0);
  REQUIRE(latest.read().has_value());
  CHECK(latest.read()->rx_ns == kReports - 1);
}
