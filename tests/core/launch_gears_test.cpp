// LaunchGears: the upshifts a launch from rest makes before the filter holds the ladder's lowest measured
// gear (the base), and the count of gears below the base they make most probable.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "core/launch_gears.hpp"

using gearpulse::LaunchGears;

namespace {

constexpr double kBase = 0.0200;                     // (m/s)/Hz
constexpr double kStep = std::log(1.35);             // the base's step to the gear above it
constexpr double kIdle = 50.0, kIdleCeiling = 55.0;  // Hz

// One launch at 10 Hz: standing at idle (a fix), then the revs given, a fix every second moving, and a
// last fix at which the filter holds the gear `above` positions over the base.
void launch(LaunchGears& gears, double& t, const std::vector<double>& revs, int above) {
  gears.observe_fix(t, true, kBase, -1);
  gears.observe_revs(kIdle, kStep, kIdleCeiling);
  for (std::size_t k = 0; k < revs.size(); ++k) {
    t += 0.1;
    gears.observe_revs(revs[k], kStep, kIdleCeiling);
    if (k % 10 == 5) gears.observe_fix(t, false, kBase, -1);
  }
  gears.observe_fix(t, false, kBase, above);
  t += 10.0;
}

// Revs climbing from `from` to `to` in `n` readings.
void climb(std::vector<double>& revs, double from, double to, int n) {
  for (int k = 0; k < n; ++k)
    revs.push_back(from + (to - from) * k / (n - 1));
}

}  // namespace

TEST_CASE("launch gears: one upshift before the base is one gear below it") {
  LaunchGears gears;
  double t = 0.0;
  std::vector<double> revs;
  climb(revs, 80.0, 250.0, 20);   // first gear
  climb(revs, 180.0, 200.0, 10);  // second, the base: the revs fell by first gear's step
  launch(gears, t, revs, 0);
  CHECK(gears.launches(1) == 1.0);
  CHECK(gears.launches(-1) == 0.0);  // no count outside 0..kMaxBelow
  CHECK(gears.launches(LaunchGears::kMaxBelow + 1) == 0.0);
  CHECK(gears.gears_below(kBase, 0, 0.1) == 1);
  CHECK(gears.gears_below(kBase * 1.2, 0, 0.1) == 0);  // another base: nothing counted on it
}

TEST_CASE("launch gears: a gear passed with no climb of the revs counts by the steps its fall spans") {
  // First gear to 250 Hz, second held for a moment only (the revs never climb in it), third from 130 Hz:
  // one fall spanning two steps, then the filter holds the gear above the base.
  LaunchGears gears;
  double t = 0.0;
  std::vector<double> revs;
  climb(revs, 80.0, 250.0, 20);
  climb(revs, 230.0, 130.0, 6);  // falling through second into third
  climb(revs, 135.0, 170.0, 15);
  launch(gears, t, revs, 1);
  CHECK(gears.launches(1) == 1.0);  // two upshifts, one of them into the gear above the base

  // The same fall ending in the idle band (the clutch out, the revs at idle) counts once: it tells
  // nothing of the gears passed.
  LaunchGears idle;
  std::vector<double> to_idle;
  climb(to_idle, 80.0, 250.0, 20);
  climb(to_idle, 200.0, 52.0, 6);
  climb(to_idle, 130.0, 170.0, 15);
  launch(idle, t, to_idle, 0);
  CHECK(idle.launches(1) == 1.0);
}

TEST_CASE("launch gears: the count most probable weighs launches against each other and the idle") {
  LaunchGears gears;
  double t = 0.0;
  std::vector<double> from_base;
  climb(from_base, 80.0, 250.0, 20);
  for (int k = 0; k < 3; ++k)
    launch(gears, t, from_base, 0);  // no upshift before the base
  CHECK(gears.gears_below(kBase, 0, 0.1) == 0);
  std::vector<double> below;
  climb(below, 80.0, 250.0, 20);
  climb(below, 180.0, 200.0, 10);
  launch(gears, t, below, 0);  // one launch against three: off by one
  CHECK(gears.gears_below(kBase, 0, 0.1) == 0);
  CHECK(gears.gears_below(kBase, 2, 0.1) == 0);  // four launches outweigh the idle's two gears
  for (int k = 0; k < 3; ++k)
    launch(gears, t, below, 0);
  CHECK(gears.gears_below(kBase, 0, 0.1) == 1);  // four against three
}

TEST_CASE("launch gears: launches from the base overrule the idle's bound only as evidence outweighs it") {
  // A motorcycle idles at 1100-1500 rpm: its first gear carries it faster at idle than a car's bound, and
  // the idle asks gears below a base that is first. Its launches show none: no upshift before the base.
  std::vector<double> from_base;
  climb(from_base, 80.0, 250.0, 20);
  LaunchGears gears;
  double t = 0.0;
  CHECK(gears.gears_below(kBase, 1, 0.1) == 1);  // nothing counted: the idle decides
  launch(gears, t, from_base, 0);
  CHECK(gears.gears_below(kBase, 1, 0.1) == 0);  // one launch against the idle's one gear
  CHECK(gears.gears_below(kBase, 2, 0.1) == 2);  // not against two
  launch(gears, t, from_base, 0);
  CHECK(gears.gears_below(kBase, 2, 0.1) == 0);  // two launches do
}

TEST_CASE("launch gears: a launch that loses GPS or crawls past the launch time is not counted") {
  std::vector<double> below;
  climb(below, 80.0, 250.0, 20);
  climb(below, 180.0, 200.0, 10);
  double t = 0.0;

  // GPS lost after the upshift: the fixes that follow it belong to no launch seen whole.
  LaunchGears lost;
  lost.observe_fix(t, true, kBase, -1);
  for (std::size_t k = 0; k < below.size(); ++k) {
    t += 0.1;
    lost.observe_revs(below[k], kStep, kIdleCeiling);
    if (k == 5) lost.observe_fix(t, false, kBase, -1);
  }
  lost.abort();
  lost.observe_fix(t + 1.0, false, kBase, 0);
  CHECK(lost.launches(1) == 0.0);
  CHECK(lost.gears_below(kBase, 0, 0.1) == 0);

  // The base held only 30 s after moving off: a crawl, not a launch.
  LaunchGears crawl;
  crawl.observe_fix(t, true, kBase, -1);
  crawl.observe_revs(kIdle, kStep, kIdleCeiling);
  const double moved = t + 0.5;
  for (std::size_t k = 0; k < below.size(); ++k) {
    crawl.observe_revs(below[k], kStep, kIdleCeiling);
    crawl.observe_fix(moved + k, false, kBase, -1);
  }
  crawl.observe_fix(moved + 30.0, false, kBase, 0);
  CHECK(crawl.launches(1) == 0.0);

  // The same launch holding the base within the launch time is counted.
  LaunchGears quick;
  quick.observe_fix(t, true, kBase, -1);
  quick.observe_revs(kIdle, kStep, kIdleCeiling);
  for (std::size_t k = 0; k < below.size(); ++k) {
    quick.observe_revs(below[k], kStep, kIdleCeiling);
    quick.observe_fix(moved + 0.1 * static_cast<double>(k), false, kBase, -1);
  }
  quick.observe_fix(moved + 5.0, false, kBase, 0);
  CHECK(quick.launches(1) == 1.0);
}

TEST_CASE("launch gears: the fit's launches centre the prior higher, never lower, and a drive's decide") {
  std::vector<double> from_base;
  climb(from_base, 80.0, 250.0, 20);
  // The fit's log: ten launches with an upshift before the base, seven with none (a first gear passed
  // between two readings leaves no fall).
  LaunchGears gears;
  gears.seed(kBase, {7.0, 10.0, 0.0, 0.0, 0.0});
  CHECK(gears.gears_below(kBase, 0, 0.1) == 1);        // the fit's launches ask one gear below
  CHECK(gears.gears_below(kBase * 1.2, 0, 0.1) == 0);  // another base: the fit's counts are not of it
  CHECK(gears.launches(1) == 0.0);                     // the drive's own counts are apart
  double t = 0.0;
  launch(gears, t, from_base, 0);
  CHECK(gears.gears_below(kBase, 0, 0.1) == 0);  // one launch of the drive against the prior's one gear

  // Counts that show the base is first never take back the gears the idle asks.
  LaunchGears first;
  first.seed(kBase, {12.0, 0.0, 0.0, 0.0, 0.0});
  CHECK(first.gears_below(kBase, 1, 0.1) == 1);
  CHECK(first.gears_below(kBase, 0, 0.1) == 0);
}
