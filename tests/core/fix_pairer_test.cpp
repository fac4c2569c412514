#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <vector>

#include "core/fix_pairer.hpp"

using gearpulse::FixPairer;
using gearpulse::PendingFix;
using gearpulse::training_pair;

namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

std::vector<double> times(std::span<const PendingFix> fixes) {
  std::vector<double> t;
  for (const PendingFix& f : fixes)
    t.push_back(f.t);
  return t;
}

}  // namespace

TEST_CASE("pairer: a fix waits until the tracker covers its instant, then is due once") {
  FixPairer pairer(3.0);
  REQUIRE(pairer.add({10.0, 1.7e9, 12.0}));
  REQUIRE(pairer.add({10.1, 1.7e9 + 0.1, 12.5}));
  // The tracker has served up to 9.95 s: neither fix yet.
  CHECK(pairer.take_due(10.2, 9.95).empty());
  CHECK(pairer.waiting() == 2);
  // Up to 10.05 s: the first, in the order they came; the second waits on.
  const auto due = pairer.take_due(10.3, 10.05);
  REQUIRE(due.size() == 1);
  CHECK(due[0].t == 10.0);
  CHECK(due[0].speed == 12.0);
  CHECK(pairer.waiting() == 1);
  CHECK(times(pairer.take_due(10.4, 10.2)) == std::vector<double>{10.1});
  CHECK(pairer.take_due(10.5, 10.3).empty());
  CHECK(pairer.waiting() == 0);
}

TEST_CASE("pairer: without a tracker fixes are given up after the wait, not paired") {
  FixPairer pairer(3.0);
  REQUIRE(pairer.add({10.0, 0.0, 5.0}));
  REQUIRE(pairer.add({11.0, 0.0, 5.0}));
  CHECK(pairer.take_due(12.9, kNan).empty());
  CHECK(pairer.waiting() == 2);
  // 3 s after the first: it is given up, the second waits on.
  CHECK(pairer.take_due(13.0, kNan).empty());
  CHECK(pairer.waiting() == 1);
  CHECK(pairer.take_due(14.0, kNan).empty());
  CHECK(pairer.waiting() == 0);
  // A fix the tracker covers is due however long it waited: the wait bounds a fix not yet covered.
  REQUIRE(pairer.add({20.0, 0.0, 5.0}));
  CHECK(times(pairer.take_due(29.0, 20.5)) == std::vector<double>{20.0});
}

TEST_CASE("pairer: the queue holds a fixed number of fixes and refuses the next") {
  FixPairer pairer(3.0);
  for (std::size_t i = 0; i < FixPairer::kCapacity; ++i)
    REQUIRE(pairer.add({10.0 + 0.01 * static_cast<double>(i), 0.0, 1.0}));
  CHECK_FALSE(pairer.add({11.0, 0.0, 1.0}));
  CHECK(pairer.take_due(11.0, 20.0).size() == FixPairer::kCapacity);
  CHECK(pairer.add({11.0, 0.0, 1.0}));
}

TEST_CASE("pairer: only a tracked, finite frequency above the SNR threshold makes a training pair") {
  const PendingFix fix{10.0, 1.7e9, 14.0};
  const auto pair = training_pair(fix, 95.0, 6.0, true, -10.0);
  REQUIRE(pair.has_value());
  CHECK(pair->t == 1.7e9);  // the store keeps wall time
  CHECK(pair->speed == 14.0);
  CHECK(pair->freq == 95.0);
  CHECK_FALSE(training_pair(fix, 95.0, 6.0, false, -10.0).has_value());
  CHECK_FALSE(training_pair(fix, kNan, 6.0, true, -10.0).has_value());
  CHECK_FALSE(training_pair(fix, 95.0, kNan, true, -10.0).has_value());
  CHECK_FALSE(training_pair(fix, 95.0, -12.0, true, -10.0).has_value());
  CHECK(training_pair(fix, 95.0, -10.0, true, -10.0).has_value());
}

TEST_CASE("pairer: one pair a second of the receiver's clock, every fix of a 1 Hz receiver") {
  using gearpulse::PairSpacing;
  SECTION("10 Hz: the first fix of each second") {
    PairSpacing spacing;
    std::vector<double> paired;
    for (int k = 0; k < 30; ++k) {
      const double fix_time = 1.7e9 + 0.1 * k, t = 100.0 + 0.1 * k;
      if (spacing.take(fix_time, t)) paired.push_back(t);
    }
    REQUIRE(paired.size() == 3);
    CHECK(paired[0] == Approx(100.0));
    CHECK(paired[1] == Approx(101.0));
    CHECK(paired[2] == Approx(102.0));
  }
  SECTION("1 Hz, received with jitter: all") {
    PairSpacing spacing;
    for (int k = 0; k < 20; ++k)
      CHECK(spacing.take(1.7e9 + k, 100.0 + k + (k % 2 == 0 ? 0.04 : -0.04)));
  }
  SECTION("no receiver time, or one standing still: by receive time") {
    PairSpacing spacing;
    CHECK(spacing.take(kNan, 10.0));
    CHECK_FALSE(spacing.take(kNan, 10.5));
    CHECK(spacing.take(kNan, 10.95));
    CHECK(spacing.take(1.7e9, 11.0));
    CHECK_FALSE(spacing.take(1.7e9, 11.5));
    CHECK(spacing.take(1.7e9, 12.0));
  }
}
