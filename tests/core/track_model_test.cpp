#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "core/track_model.hpp"

using gearpulse::TrackerConfig;
using gearpulse::TrackModel;

namespace {

constexpr double kDf = 0.5;  // Hz per state
constexpr int kFirst = 50, kLast = 400;

// One hop: `llr` at every state within 2 Hz of each line, `elsewhere` at the rest; the window hides the
// line with probability `hidden`.
void hop(TrackModel& model, const std::vector<std::pair<double, double>>& lines, double elsewhere,
         double hidden = 0.0) {
  model.predict();
  std::vector<double>& e = model.evidence();
  for (int k = kFirst; k <= kLast; ++k) {
    double v = elsewhere;
    for (const auto& [f, llr] : lines)
      if (std::abs(k * kDf - f) <= 2.0) v = llr;
    e[static_cast<std::size_t>(k - kFirst)] = v;
  }
  REQUIRE(model.update(hidden));
}

}  // namespace

// After a few hops whose windows showed no line (a shift's smear), the posterior sits on "engine absent".
// A hop that then shows the engine's line and, a little louder, a line at twice its frequency (a loud 2nd
// harmonic read as a fundamental): the engine is found again near where it was last tracked, not at the
// louder line a uniform restart would take.
TEST_CASE(
    "track model: a line found again after the track lost it is found near the latest tracked estimate") {
  TrackModel model(TrackerConfig{}, kFirst, kLast, kDf, 4);
  for (int i = 0; i < 10; ++i) {
    hop(model, {{100.0, 8.0}}, 0.0);
    const double f = model.mode_bin() * kDf;
    model.observe(f, model.mass_near(f), true);
  }
  CHECK(std::abs(model.mode_bin() * kDf - 100.0) <= 2.0);
  for (int i = 0; i < 3; ++i) {
    hop(model, {}, -5.0);
    const double f = model.mode_bin() * kDf;
    model.observe(f, model.mass_near(f), false);
  }
  hop(model, {{100.0, 6.0}, {200.0, 7.0}}, 0.0);
  INFO("mode " << model.mode_bin() * kDf << " Hz");
  CHECK(std::abs(model.mode_bin() * kDf - 100.0) <= 2.0);
  CHECK(model.mass_near(100.0) > model.mass_near(200.0));
}

// A line rising at 20 Hz/s (an engine under power) is followed to 120 Hz; then three windows show nothing
// (a gear shift's smear) and the next shows two equal lines: at 0.65 of the old line (the new gear's
// fundamental) and at 1.3 of it (the new gear's 2nd harmonic, a little louder). A rising line's shift is
// an upshift, which lowers the revs by the gear step; the revs do not rise by a third while the line is
// hidden. The posterior favours the lower line.
TEST_CASE("track model: a rising line lost in a gear shift is found again below, not at a line above") {
  TrackModel model(TrackerConfig{}, kFirst, kLast, kDf, 4);
  const double hop_s = TrackerConfig{}.hop_s;
  double f = 90.0;
  for (int i = 0; i <= 15; ++i, f += 20.0 * hop_s) {
    hop(model, {{f, 3.0}}, 0.0);
    const double mode = model.mode_bin() * kDf;
    model.observe(mode, model.mass_near(mode), true);
  }
  const double old_line = f - 20.0 * hop_s;
  REQUIRE(model.mass_near(old_line) >= 0.8);
  for (int i = 0; i < 3; ++i) {
    hop(model, {}, -1.0);
    const double mode = model.mode_bin() * kDf;
    model.observe(mode, model.mass_near(mode), false);
  }
  const double below = 0.65 * old_line, above = 1.3 * old_line;
  hop(model, {{below, 3.0}, {above, 3.5}}, -1.0);
  INFO("old line " << old_line << " Hz; posterior near " << below << " Hz " << model.mass_near(below)
                   << ", near " << above << " Hz " << model.mass_near(above));
  CHECK(model.mass_near(below) >= 2.0 * model.mass_near(above));
}

// Far from the latest tracked estimate (long ago: the engine may have stopped or moved anywhere), the
// louder line wins.
TEST_CASE("track model: long after the latest tracked estimate a line is found wherever it is loudest") {
  TrackModel model(TrackerConfig{}, kFirst, kLast, kDf, 4);
  for (int i = 0; i < 10; ++i) {
    hop(model, {{100.0, 8.0}}, 0.0);
    const double f = model.mode_bin() * kDf;
    model.observe(f, model.mass_near(f), true);
  }
  for (int i = 0; i < 600; ++i) {  // a minute with the engine off
    hop(model, {}, -5.0);
    model.observe(model.mode_bin() * kDf, 0.0, false);
  }
  hop(model, {{100.0, 6.0}, {190.0, 7.0}}, 0.0);
  CHECK(std::abs(model.mode_bin() * kDf - 190.0) <= 2.0);
}

// A weak line followed for a second, then one window in which it is missing (the states within 6 Hz of it
// read -6, the rest 0): with no allowance for a window that hides the line the posterior passes to
// "engine absent" and the next window that shows the line leaves it unconfident; allowing one in three
// windows to hide it, the track keeps the line, and the next window that shows it is confident again.
TEST_CASE("track model: a window that hides the line does not throw the track away") {
  const double hidden = GENERATE(0.0, 0.3);
  INFO("hidden " << hidden);
  TrackModel model(TrackerConfig{}, kFirst, kLast, kDf, 4);
  for (int i = 0; i < 10; ++i) {
    hop(model, {{100.0, 3.0}}, 0.0, hidden);
    const double f = model.mode_bin() * kDf;
    model.observe(f, model.mass_near(f), true);
  }
  REQUIRE(model.mass_near(100.0) >= 0.9);
  hop(model, {{96.0, -6.0}, {100.0, -6.0}, {104.0, -6.0}}, 0.0, hidden);
  const double kept = model.mass_near(100.0);
  model.observe(100.0, kept, false);
  hop(model, {{100.0, 3.0}}, 0.0, hidden);
  INFO("posterior near the line: " << kept << " in the missing window, " << model.mass_near(100.0)
                                   << " in the next");
  if (hidden > 0.0) {
    CHECK(kept >= 0.5);
    CHECK(model.mass_near(100.0) >= 0.8);
  } else {
    CHECK(kept < 0.1);
    CHECK(model.mass_near(100.0) < 0.8);
  }
}

// The overrun's evidence (a loud 2nd harmonic read as likely) is read by the layers of a line falling at
// TrackModel::kOverrunHzPerS or faster: a weak line's posterior grows with it while the line falls fast,
// and hardly while it holds still.
TEST_CASE("track model: the overrun's evidence counts for a fast falling line only") {
  const double rate = GENERATE(0.0, -30.0);  // Hz/s
  INFO("line at " << rate << " Hz/s");
  double near[2] = {0.0, 0.0};
  for (int with = 0; with < 2; ++with) {
    TrackModel model(TrackerConfig{}, kFirst, kLast, kDf, 4);
    double f = 150.0;
    for (int i = 0; i < 15; ++i) {
      std::vector<double>& excess = model.overrun_excess();
      for (int k = kFirst; k <= kLast; ++k)
        excess[static_cast<std::size_t>(k - kFirst)] = with && std::abs(k * kDf - f) <= 2.0 ? 0.7 : 0.0;
      hop(model, {{f, 0.5}}, -0.2);
      f += rate * TrackerConfig{}.hop_s;
    }
    near[with] = model.mass_near(f - rate * TrackerConfig{}.hop_s);
  }
  INFO("posterior near the line: " << near[0] << " without the overrun's evidence, " << near[1]
                                   << " with it");
  // A steady line gains a little: its mass whose rate changes passes through the falling layers.
  if (rate < 0.0) {
    CHECK(near[1] >= near[0] + 0.3);
  } else {
    CHECK(near[1] <= near[0] + 0.1);
  }
}

// Where an upshift from the latest tracked estimate leads (0.55-0.85 of it), a steady line reads the better
// of the usual and the overrun's evidence (a new gear's first windows at light load, the 2nd harmonic loud);
// a steady line elsewhere (at twice the new gear) reads the usual evidence alone.
TEST_CASE("track model: a line where an upshift leads reads the overrun's evidence, one above it does not") {
  double near[2][2] = {};  // [with the overrun's excess][the line at 100 Hz, at 200 Hz]
  for (int with = 0; with < 2; ++with) {
    TrackModel model(TrackerConfig{}, kFirst, kLast, kDf, 4);
    for (int i = 0; i < 10; ++i) {
      hop(model, {{150.0, 3.0}}, -0.2);
      model.observe(150.0, 0.95, true);
    }
    for (int i = 0; i < 3; ++i) {
      hop(model, {}, 0.0);
      model.observe(150.0, 0.1, false);
    }
    for (int i = 0; i < 5; ++i) {
      std::vector<double>& excess = model.overrun_excess();
      for (int k = kFirst; k <= kLast; ++k) {
        const double f = k * kDf;
        excess[static_cast<std::size_t>(k - kFirst)] =
            with && (std::abs(f - 100.0) <= 2.0 || std::abs(f - 200.0) <= 2.0) ? 0.7 : 0.0;
      }
      hop(model, {{100.0, 0.3}, {200.0, 0.3}}, -0.2);
      model.observe(100.0, 0.3, false);
    }
    near[with][0] = model.mass_near(100.0);
    near[with][1] = model.mass_near(200.0);
  }
  INFO("posterior near 100 Hz: " << near[0][0] << " without the overrun's evidence, " << near[1][0]
                                 << " with it; near 200 Hz: " << near[0][1] << ", " << near[1][1]);
  // The faint lines hold little of the posterior in five hops; what counts is the ratio the excess gives.
  CHECK(near[1][0] >= 2.0 * near[0][0]);
  CHECK(near[1][1] <= 1.1 * near[0][1]);
}
