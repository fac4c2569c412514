#include <catch2/catch.hpp>

#include <array>
#include <cmath>

#include "core/seen_gears.hpp"

using gearpulse::SeenGears;

namespace {

// A ladder of the model: 2nd to 5th of a hatch; the car drives in a 1st it lacks (0.13 (m/s)/Hz).
constexpr std::array<double, 4> kModel{0.2434, 0.3538, 0.4495, 0.5830};
constexpr double kFirst = 0.13;

// Fixes once a second for `seconds` s, the car in first gear gaining `growth` of its speed a second from
// 3 m/s, each fix `late` s late against the revs; the synthesis takes the fix as `lag` s late. Returns how
// many gears are seen and the first one's theta.
int sight(double growth, double late, double lag, double& theta) {
  SeenGears seen(2.0);
  for (int k = 0; k < 8; ++k) {
    const double t = k;
    const double speed = 3.0 * std::exp(growth * t);
    const double revs = 3.0 * std::exp(growth * (t + late)) / kFirst;  // the engine's, `late` s on
    seen.observe(t, speed, revs, 15.0, kModel, lag);
  }
  std::array<SeenGears::Gear, SeenGears::kCapacity> gears{};
  const int n = seen.seen(gears);
  theta = n > 0 ? gears[0].theta : 0.0;
  return n;
}

}  // namespace

TEST_CASE("seen gears: a steady gear the model lacks is seen at its ratio") {
  double theta = 0.0;
  REQUIRE(sight(0.0, 0.5, 0.5, theta) == 1);
  CHECK(theta == Approx(kFirst).epsilon(0.001));
}

TEST_CASE("seen gears: a fix later than half a second sights a gear only at a speed steadier by as much") {
  // Gaining 1.5 % a second with fixes 0.9 s late, the ratio reads 1.35 % low: beyond the 1 % a sighting
  // allows, so no gear is seen (at 2 % a second, the bound for fixes 0.5 s late, one would be).
  double theta = 0.0;
  CHECK(sight(0.015, 0.9, 0.9, theta) == 0);
  // Half a second late, the same gain biases the ratio by 0.75 %: the gear is seen, within that of its ratio.
  REQUIRE(sight(0.015, 0.5, 0.5, theta) == 1);
  CHECK(theta == Approx(kFirst).epsilon(0.01));
  // A lag below half a second is no licence for a faster change: a fix's own timing scatters by that much.
  CHECK(sight(0.03, 0.0, 0.0, theta) == 0);
}

TEST_CASE("seen gears: a gear sighted only at lugged revs is a possible creep until sighted above them") {
  // A car crawling in a queue at 1.1 m/s, its clutch slipping with the revs held at 15.8 Hz (lugged: below
  // the revs the driver holds any gear above first at): a steady ratio of 0.07, off every gear of the model.
  SeenGears seen(2.0);
  // The first fix has no neighbour; the next two are sightings in a row, and the gear is seen at the second.
  for (int k = 0; k < 4; ++k)
    CHECK(seen.observe(k, 1.1, 15.8, 15.0, kModel, 0.5, true) == (k == 2));
  std::array<SeenGears::Gear, SeenGears::kCapacity> gears{};
  REQUIRE(seen.seen(gears) == 1);
  CHECK(gears[0].theta == Approx(1.1 / 15.8).epsilon(0.001));
  CHECK(gears[0].creep);
  // The same ratio held at revs not lugged is a gear's: its first such sighting changes the gears seen.
  CHECK_FALSE(seen.observe(4.0, 2.2, 31.6, 15.0, kModel, 0.5, false));  // the speed changed: no sighting
  CHECK(seen.observe(5.0, 2.2, 31.6, 15.0, kModel, 0.5, false));
  CHECK_FALSE(seen.observe(6.0, 2.2, 31.6, 15.0, kModel, 0.5, false));
  REQUIRE(seen.seen(gears) == 1);
  CHECK_FALSE(gears[0].creep);
}
