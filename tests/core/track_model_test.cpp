#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "core/track_model.hpp"

using gearpulse::TrackerConfig;
using gearpulse::TrackModel;

namespace {

constexpr double kDf = 0.5;  // Hz per state
constexpr int kFirst = 50, kLast = 400;

// One hop: `llr` at every state within 2 Hz of each line, `elsewhere` at the rest.
void hop(TrackModel& model, const std::vector<std::pair<double, double>>& lines, double elsewhere) {
  model.predict();
  std::vector<double>& e = model.evidence();
  for (int k = kFirst; k <= kLast; ++k) {
    double v = elsewhere;
    for (const auto& [f, llr] : lines)
      if (std::abs(k * kDf - f) <= 2.0) v = llr;
    e[static_cast<std::size_t>(k - kFirst)] = v;
  }
  REQUIRE(model.update());
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
