#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <optional>

#include "daemon/synthesis_stage.hpp"
#include "tests/town_drive.hpp"

using gearpulse::GpsReport;
using gearpulse::SpeedSource;
using gearpulse::daemon::SynthesisStage;

namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

GpsReport fix(double speed, double fix_time) {
  GpsReport r;
  r.rx_ns = static_cast<std::int64_t>(fix_time * 1e9);
  r.speed = speed;
  r.mode = 3;
  r.fix_time = fix_time;
  return r;
}

}  // namespace

TEST_CASE("synthesis: a frequency is used only when tracked, finite and at least the SNR threshold") {
  SynthesisStage stage;
  CHECK(stage.step(1.0, 90.0, 5.0, true, std::nullopt, -10.0).confident);
  CHECK_FALSE(stage.step(1.1, 90.0, 5.0, false, std::nullopt, -10.0).confident);
  CHECK_FALSE(stage.step(1.2, kNan, 5.0, true, std::nullopt, -10.0).confident);
  CHECK_FALSE(stage.step(1.3, 90.0, -11.0, true, std::nullopt, -10.0).confident);
  CHECK(stage.step(1.4, 90.0, -10.0, true, std::nullopt, -10.0).confident);
}

TEST_CASE("synthesis: with a fresh fix the speed is GPS's, and steps never go back in time") {
  SynthesisStage stage;
  SynthesisStage::Step s{};
  for (int i = 0; i < 20; ++i)
    s = stage.step(10.0 + 0.1 * i, kNan, kNan, false, fix(12.0, 1000.0 + 0.1 * i), -10.0);
  CHECK(s.out.source == SpeedSource::kGps);
  CHECK(std::abs(s.out.speed - 12.0) < 0.5);
  const double last = stage.last_step_time();
  CHECK(last == Approx(11.9));
  (void)stage.step(5.0, kNan, kNan, false, std::nullopt, -10.0);  // a point stamped before the last step
  CHECK(stage.last_step_time() == last);
}

TEST_CASE("synthesis: a fix is stamped at its receive time less gps.latency, as the training pairs are") {
  // The first move-off of a town drive, each fix received 0.5 s after its moment and gps.latency 0.5: the
  // pairs the model was fitted on were stamped at their moment, so it found no lag left. Stamped at its
  // receive time, a fix was the speed of its step: -8.8 % over the outage.
  const auto run = [](double latency) {
    SynthesisStage stage;
    REQUIRE(stage.set_model(gearpulse::test::hatch_model(0.0)));
    std::optional<GpsReport> last;
    return gearpulse::test::first_launch_outage_error([&](double t, double gps, double freq, bool is_new) {
      if (is_new) last = fix(gps, t);  // received at this step
      const std::optional<GpsReport> fresh = std::isfinite(gps) ? last : std::nullopt;
      return stage.step(t, freq, 30.0, true, fresh, -10.0, latency).out.speed;
    });
  };
  const double error = run(0.5);
  INFO("outage distance error " << error << " % (" << run(0.0) << " % with gps.latency 0)");
  CHECK(std::abs(error) < 2.0);
}

TEST_CASE("synthesis: the stage's band_low is the readings' floor, also for a model set after it") {
  // The daemon builds the stage once with tracker.band_low and sets the model after: an idle the fit put
  // below the band is then not learned from what is read at rest (a clutch slipping at half as much
  // again, the fix at rest). A stage built without the floor learns it as a high idle.
  auto model = std::make_shared<gearpulse::GearModel>(*gearpulse::test::hatch_model());
  const double idle = gearpulse::test::kIdle;
  model->extra["idle"] = {{"freq", idle}, {"sd", 0.3}, {"samples", 500}};
  const auto idle_after = [&](SynthesisStage stage) {
    REQUIRE(stage.set_model(model));
    for (int i = 0; i < 100; ++i) {
      const double t = 10.0 + 0.1 * i;
      (void)stage.step(t, 1.5 * idle, 30.0, true, fix(0.0, t), -10.0);
    }
    return stage.idle_freq();
  };
  CHECK(idle_after(SynthesisStage(1.2 * idle)) == Approx(idle));
  CHECK(idle_after(SynthesisStage()) > 1.4 * idle);
}
