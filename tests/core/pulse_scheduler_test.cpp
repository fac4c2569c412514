#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "core/pulse_scheduler.hpp"

using gearpulse::EdgeKind;
using gearpulse::PulseConfig;
using gearpulse::PulseEdge;
using gearpulse::PulseScheduler;

namespace {

constexpr std::int64_t kS = 1'000'000'000;

// Drives the scheduler like the pulse thread does, but in simulated time: edges are committed at their
// scheduled instants, speed changes at `changes` (t_ns, speed). Returns the edges.
struct Run {
  std::vector<PulseEdge> edges;
  std::uint64_t pulses = 0;
};

Run drive(PulseScheduler& s, const std::vector<std::pair<std::int64_t, double>>& changes, std::int64_t end) {
  Run run;
  std::size_t next = 0;
  for (;;) {
    const std::int64_t change_t = next < changes.size() ? changes[next].first : end;
    const PulseEdge e = s.next_edge();
    if (e.kind != EdgeKind::kNone && e.t_ns <= change_t && e.t_ns <= end) {
      run.edges.push_back(s.pop_due(e.t_ns));
      continue;
    }
    if (next >= changes.size()) break;
    s.set_speed(changes[next].first, changes[next].second);
    ++next;
  }
  run.pulses = s.pulses();
  return run;
}

double distance_m(const std::vector<std::pair<std::int64_t, double>>& changes, std::int64_t end) {
  double d = 0;
  for (std::size_t i = 0; i < changes.size(); ++i) {
    const std::int64_t t1 = i + 1 < changes.size() ? changes[i + 1].first : end;
    d += changes[i].second * static_cast<double>(t1 - changes[i].first) / kS;
  }
  return d;
}

}  // namespace

TEST_CASE("pulse: constant speed gives the exact frequency and duty") {
  PulseConfig c;
  c.pulses_per_km = 1000.0;  // 1 pulse per metre
  PulseScheduler s(c, 0);
  s.set_speed(0, 20.0);  // 20 Hz
  const Run r = drive(s, {}, 10 * kS);
  REQUIRE(r.pulses == 200);  // rise k at k / 20 s, k = 1..200
  REQUIRE(r.edges.size() >= 399);
  CHECK(r.edges[0].kind == EdgeKind::kRise);
  CHECK(r.edges[0].t_ns == 50'000'000);
  CHECK(r.edges[1].kind == EdgeKind::kFall);
  CHECK(r.edges[1].t_ns == 75'000'000);  // duty 0.5
  CHECK(r.edges[2].t_ns == 100'000'000);
}

TEST_CASE("pulse: a slow pulse high when the speed rises falls at the new frequency's duty") {
  // 1 pulse per metre. At 0.5 m/s a pulse rises at 2 s and, at duty 0.5, would stay high for 1 s; at 2.1 s
  // the car is at 50 m/s. Held high to 3 s, the line would owe 45 pulses by then and the count would trail
  // the distance for seconds; it falls at once and the train keeps within a pulse of the distance.
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.min_freq_hz = 0.01;
  c.max_freq_hz = 1e6;
  PulseScheduler s(c, 0);
  const std::vector<std::pair<std::int64_t, double>> changes = {{0, 0.5}, {2 * kS + kS / 10, 50.0}};
  for (const std::int64_t end : {2 * kS + kS / 5, 3 * kS, 5 * kS}) {
    PulseScheduler run_s = s;
    const Run r = drive(run_s, changes, end);
    INFO("at " << end << " ns: " << r.pulses << " pulses for " << distance_m(changes, end) << " m");
    CHECK(std::fabs(static_cast<double>(r.pulses) - distance_m(changes, end)) <= 1.0);
    REQUIRE(r.edges.size() >= 2);
    CHECK(r.edges[1].kind == EdgeKind::kFall);
    CHECK(r.edges[1].t_ns == 2 * kS + kS / 10);  // the first pulse's fall, brought forward to the change
  }
}

TEST_CASE("pulse: count equals distance times pulses per km over random profiles") {
  const unsigned seed = std::random_device{}();
  INFO("seed " << seed);
  std::printf("pulse: random profile seed %u\n", seed);
  std::mt19937_64 rng(seed);
  for (int trial = 0; trial < 50; ++trial) {
    PulseConfig c;
    c.pulses_per_km = std::uniform_real_distribution<double>(500, 20000)(rng);
    c.max_freq_hz = 1e6;  // never clamp here
    c.min_freq_hz = 0.01;
    if (trial % 2) c.pulse_width_s = 1e-7;
    PulseScheduler s(c, 0);
    std::vector<std::pair<std::int64_t, double>> changes;
    std::int64_t t = 0;
    const std::int64_t end = 120 * kS;
    std::uniform_int_distribution<std::int64_t> gap(1, 3 * kS);
    std::uniform_real_distribution<double> speed(0.5, 60.0);
    while (t < end) {
      const double v = (rng() % 7 == 0) ? 0.0 : speed(rng);  // standstills too
      changes.emplace_back(t, v);
      t += gap(rng);
    }
    const Run r = drive(s, changes, end);
    const double expected = distance_m(changes, end) * c.pulses_per_km / 1000.0;
    INFO("trial " << trial << " expected " << expected << " got " << r.pulses);
    CHECK(std::fabs(static_cast<double>(r.pulses) - expected) <= 1.0);
    CHECK(s.phase_pulses(end) == Approx(expected).epsilon(1e-9));
    // Edges alternate rise/fall and never go back in time.
    bool ordered = true;
    for (std::size_t i = 1; i < r.edges.size(); ++i)
      ordered = ordered && r.edges[i].t_ns >= r.edges[i - 1].t_ns && r.edges[i].kind != r.edges[i - 1].kind;
    CHECK(ordered);
  }
}

TEST_CASE("pulse: zero speed stops cleanly and resumes with the phase it had") {
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 10.0);                                  // a pulse every 100 ms
  const Run a = drive(s, {{250'000'000, 0.0}}, 5 * kS);  // stop after 2.5 periods
  CHECK(a.pulses == 2);
  CHECK_FALSE(s.high());  // the last pulse fell
  CHECK(s.next_edge().kind == EdgeKind::kNone);
  s.set_speed(5 * kS, 10.0);
  // Half a period was owed: the next rise comes 50 ms after restarting, not 100 ms.
  CHECK(s.next_edge().kind == EdgeKind::kRise);
  CHECK(s.next_edge().t_ns == 5 * kS + 50'000'000);
}

TEST_CASE("pulse: a stop while the line is high still lets it fall") {
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 10.0);
  REQUIRE(s.pop_due(100'000'000).kind == EdgeKind::kRise);
  s.set_speed(120'000'000, 0.0);
  CHECK(s.high());
  const PulseEdge fall = s.next_edge();
  CHECK(fall.kind == EdgeKind::kFall);
  CHECK(fall.t_ns == 150'000'000);
  CHECK(s.pop_due(fall.t_ns).kind == EdgeKind::kFall);
  CHECK(s.next_edge().kind == EdgeKind::kNone);
}

TEST_CASE("pulse: below the minimum frequency there is no pulse and above the maximum it clamps") {
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.min_freq_hz = 0.5;
  c.max_freq_hz = 100.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 0.3);  // 0.3 Hz < min
  CHECK(s.frequency_hz() == 0.0);
  CHECK(drive(s, {}, 20 * kS).pulses == 0);
  s.set_speed(20 * kS, 500.0);  // 500 Hz > max
  CHECK(s.frequency_hz() == 100.0);
  CHECK(drive(s, {}, 30 * kS).pulses == 1000);
  s.set_speed(30 * kS, std::nan(""));
  CHECK(s.frequency_hz() == 0.0);
  s.set_speed(30 * kS, -4.0);
  CHECK(s.frequency_hz() == 0.0);
}

TEST_CASE("pulse: fixed width and late callers keep the count and a low gap") {
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.pulse_width_s = 0.002;
  c.max_freq_hz = 200.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 100.0);  // 100 Hz
  // A caller that wakes only every 50 ms gets the overdue edges one after another, in order.
  std::uint64_t rises = 0;
  std::int64_t last_fall = -kS, last_rise = -kS;
  for (std::int64_t now = 0; now <= kS; now += 50'000'000) {
    for (PulseEdge e = s.pop_due(now); e.kind != EdgeKind::kNone; e = s.pop_due(now)) {
      if (e.kind == EdgeKind::kRise) {
        ++rises;
        CHECK(e.t_ns - last_rise >= 5'000'000);  // never faster than max_freq_hz
        last_rise = e.t_ns;
      } else {
        CHECK(e.t_ns - last_rise == 2'000'000);
        last_fall = e.t_ns;
      }
    }
  }
  CHECK(rises == 100);
  CHECK(last_fall > 0);
}

TEST_CASE("pulse: bad configurations are refused with the field name") {
  PulseConfig c;
  c.pulses_per_km = 0;
  CHECK_THROWS_WITH(PulseScheduler(c), Catch::Contains("pulses_per_km"));
  c = {};
  c.duty = 1.0;
  CHECK_THROWS_WITH(PulseScheduler(c), Catch::Contains("duty"));
  c = {};
  c.pulse_width_s = 0.01;
  c.max_freq_hz = 200;
  CHECK_THROWS_WITH(PulseScheduler(c), Catch::Contains("pulse_width_s"));
  c = {};
  c.min_freq_hz = 0;
  CHECK_THROWS_WITH(PulseScheduler(c), Catch::Contains("min_freq_hz"));
}

TEST_CASE("pulse: a late caller's catch-up rises keep the low time of the maximum frequency after a fall") {
  // 1 pulse per metre at 50 m/s (50 Hz, high 10 ms at duty 0.5), max 100 Hz. A caller that sets the speed
  // again only at 100 ms owes five pulses; caught up one after another, each rise must still come at least
  // the low time at max_freq_hz (5 ms) after the fall before it, or a counter on the line merges pulses.
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.max_freq_hz = 100.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 50.0);
  s.set_speed(100'000'000, 50.0);
  std::int64_t last_fall = -kS;
  int rises = 0;
  for (PulseEdge e = s.pop_due(200'000'000); e.kind != EdgeKind::kNone; e = s.pop_due(200'000'000)) {
    if (e.kind == EdgeKind::kFall) {
      last_fall = e.t_ns;
      continue;
    }
    ++rises;
    INFO("rise " << rises << " at " << e.t_ns << " ns, previous fall at " << last_fall << " ns");
    CHECK(e.t_ns - last_fall >= 5'000'000);
  }
  CHECK(rises >= 5);
}

TEST_CASE("pulse: edges written late keep their width and low time on the line, and the count catches up") {
  // The pulse thread's loop in simulated time: it sleeps until the next edge and writes each edge at the
  // instant it wakes, 20-120 us late, and once stalls for 30 ms (a busy machine without real-time
  // priority). 1 pulse per metre at 90 m/s (90 Hz), fixed width 2 ms, max 200 Hz: on the line every pulse
  // must stay high 2 ms and low at least the 3 ms of max_freq_hz; a rise and its fall written back to back
  // after the stall would be a pulse microseconds wide, which a counter misses.
  for (const double width_s : {0.002, 0.0}) {  // fixed width, and a duty cycle of 0.5
    INFO("pulse width " << width_s << " s");
    PulseConfig c;
    c.pulses_per_km = 1000.0;
    c.pulse_width_s = width_s;
    c.max_freq_hz = 200.0;
    PulseScheduler s(c, 0);
    s.set_speed(0, 90.0);
    std::mt19937 rng(3);
    std::uniform_int_distribution<std::int64_t> wake_late(20'000, 120'000);
    std::int64_t now = 0, rise_at = -kS, fall_at = -kS;
    std::uint64_t rises = 0;
    bool stalled = false;
    const double min_high_ns = width_s > 0 ? width_s * 1e9 : 0.5 / 200.0 * 1e9;
    const double min_low_ns = width_s > 0 ? (1.0 / 200.0 - width_s) * 1e9 : 0.5 / 200.0 * 1e9;
    while (now < 2 * kS) {
      for (PulseEdge e = s.emit_due(now); e.kind != EdgeKind::kNone; e = s.emit_due(now)) {
        INFO("edge scheduled at " << e.t_ns << " ns, written at " << now << " ns");
        if (e.kind == EdgeKind::kRise) {
          CHECK(static_cast<double>(now - fall_at) >= min_low_ns - 1.0);
          CHECK(now - rise_at >= 5'000'000 - 1);  // never faster than max_freq_hz on the line
          rise_at = now;
          ++rises;
        } else {
          CHECK(static_cast<double>(now - rise_at) >= min_high_ns - 1.0);
          fall_at = now;
        }
        now += 2'000;  // the write itself
      }
      now = std::max(now, s.next_edge().t_ns) + wake_late(rng);
      if (!stalled && now > 500'000'000) now += 30'000'000, stalled = true;
    }
    // 180 m in 2 s: the pulses owed after the stall are paid out at up to 200 Hz.
    CHECK(rises >= 179);
    CHECK(rises <= 181);
  }
}

TEST_CASE("pulse: a fixed-width pulse high when the speed rises keeps its width") {
  // Only a duty-cycle pulse is brought forward by a speed-up; a fixed width is what the receiving
  // counter was set up for, and a shorter pulse may be missed by it.
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.pulse_width_s = 0.002;
  c.max_freq_hz = 400.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 300.0);  // 300 Hz
  const PulseEdge rise = s.pop_due(10'000'000);
  REQUIRE(rise.kind == EdgeKind::kRise);
  s.set_speed(4'000'000, 400.0);
  REQUIRE(s.high());
  const PulseEdge fall = s.next_edge();
  CHECK(fall.kind == EdgeKind::kFall);
  CHECK(fall.t_ns - rise.t_ns == 2'000'000);
}

TEST_CASE("pulse: pulses owed at a stop are paid out at the maximum frequency's pace") {
  // 1 pulse per metre at 50 m/s, max 100 Hz; a caller late by 100 ms learns of the stop with five pulses
  // owed. They come out 10 ms apart, each high for duty / max_freq_hz (5 ms), so the line is quiet by
  // 145 ms; a width taken from min_freq_hz (1 s each) would keep the train running for seconds after the
  // car stopped.
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.max_freq_hz = 100.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 50.0);
  s.set_speed(100'000'000, 0.0);
  std::vector<PulseEdge> edges;
  for (PulseEdge e = s.next_edge(); e.kind != EdgeKind::kNone && edges.size() < 100; e = s.next_edge())
    edges.push_back(s.pop_due(e.t_ns));
  REQUIRE(edges.size() == 10);
  CHECK(s.pulses() == 5);
  CHECK(edges.front().t_ns == 100'000'000);
  CHECK(edges.back().kind == EdgeKind::kFall);
  CHECK(edges.back().t_ns <= 145'000'000);
}

TEST_CASE("pulse: boundary cases: exactly min_freq_hz, exactly one pulse owed, an infinite speed") {
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.min_freq_hz = 0.5;
  c.max_freq_hz = 100.0;
  SECTION("exactly min_freq_hz runs the train") {
    PulseScheduler s(c, 0);
    s.set_speed(0, 0.5);  // 0.5 Hz
    CHECK(s.frequency_hz() == 0.5);
    CHECK(s.next_edge().kind == EdgeKind::kRise);
    CHECK(s.next_edge().t_ns == 2 * kS);
  }
  SECTION("a whole pulse owed at a stop is due at once") {
    // 10 Hz for 100 ms owes exactly one pulse: it is distance covered, so it is emitted at the stop.
    PulseScheduler s(c, 0);
    s.set_speed(0, 10.0);
    s.set_speed(100'000'000, 0.0);
    CHECK(s.next_edge().kind == EdgeKind::kRise);
    CHECK(s.next_edge().t_ns == 100'000'000);
  }
  SECTION("an infinite speed is no speed, not the maximum frequency") {
    // Like NaN, an infinite speed is a broken input: it must not drive the train at full rate.
    PulseScheduler s(c, 0);
    s.set_speed(0, std::numeric_limits<double>::infinity());
    CHECK(s.frequency_hz() == 0.0);
    CHECK(s.speed_mps() == 0.0);
    CHECK(s.next_edge().kind == EdgeKind::kNone);
  }
}

TEST_CASE("pulse: a width of exactly one period and a maximum not above the minimum are refused") {
  // 5 ms at 200 Hz leaves no low time at all: pulses would merge into a level on the line.
  PulseConfig c;
  c.pulse_width_s = 0.005;
  c.max_freq_hz = 200;
  CHECK_THROWS_WITH(PulseScheduler(c), Catch::Contains("pulse_width_s"));
  c.pulse_width_s = 0.0049;
  CHECK_NOTHROW(PulseScheduler(c));
  c = {};
  c.min_freq_hz = 5;
  c.max_freq_hz = 5;
  CHECK_THROWS_WITH(PulseScheduler(c), Catch::Contains("max_freq_hz"));
  c.max_freq_hz = 4;
  CHECK_THROWS_WITH(PulseScheduler(c), Catch::Contains("max_freq_hz"));
}

TEST_CASE(
    "pulse: a line that cannot keep up owes at most half a second at the maximum, and says what it "
    "dropped") {
  // Every edge written 50 us late (a thread without real-time priority), duty 0.5, max 1000 Hz, 950 Hz
  // asked for ten minutes: the low time kept after each late fall holds the line below the rate asked, so
  // the pulses owed grow. Unbounded, 37,000 of them came out over 41 s after the car had stopped.
  PulseConfig c;
  c.pulses_per_km = 1000.0;
  c.max_freq_hz = 1000.0;
  PulseScheduler s(c, 0);
  s.set_speed(0, 950.0);
  const std::int64_t stop = 600 * kS;
  std::int64_t now = 0;
  bool stopped = false;
  std::uint64_t at_stop = 0;
  while (now < stop + 60 * kS) {
    if (!stopped && now >= stop) {
      s.set_speed(now, 0.0);
      stopped = true;
      at_stop = s.pulses();
    }
    for (PulseEdge e = s.emit_due(now); e.kind != EdgeKind::kNone; e = s.emit_due(now))
      now += 2'000;  // the write itself
    const std::int64_t next = s.next_edge().t_ns;
    if (next == PulseEdge::kNever) break;  // stopped, and nothing owed
    now = std::max(now, next) + 50'000;
  }
  REQUIRE(stopped);
  const std::uint64_t after_stop = s.pulses() - at_stop;
  INFO("pulses after the stop " << after_stop << ", discarded " << s.discarded());
  CHECK(after_stop <= 501);
  CHECK(s.discarded() > 0);
  // What the line showed and what was dropped make the distance.
  CHECK(static_cast<double>(s.pulses() + s.discarded()) == Approx(950.0 * 600.0).margin(2.0));
}
