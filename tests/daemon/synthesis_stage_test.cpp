#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "daemon/synthesis_stage.hpp"
#include "drivers/gps_history.hpp"
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

TEST_CASE("synthesis: hops stepped late in bursts get the GPS of their time, hops on time today's") {
  // A loaded machine holds the tracker thread back, and it drains the audio of seconds in one turn. Judged
  // when the thread runs, those hops got a fix newer than they are, or GPS already lost or back at an
  // outage's edge: the synthesis's input depended on scheduling. A hop stepped later than a thread keeping
  // pace steps it takes the report newest at that moment (GpsHistory::for_hop); a hop on time is judged
  // now, on the newest report, as before.
  constexpr std::int64_t kBase = 1'000'000'000'000;  // ns: CLOCK_MONOTONIC at the drive's start
  constexpr std::int64_t kTimeout = 1'500'000'000;   // ns: gps.no_fix_timeout
  constexpr double kLost = 45.0, kBack = 57.0;       // s: an outage in the second town cycle
  // s from a hop's time to when it is due (the daemon's hop_due): the test's thread gets a hop 0.1 s
  // after its time (its window given), at the latest before the next hop, 0.1 s later.
  constexpr double kDue = 0.2;
  const gearpulse::test::TownDrive drive;
  const auto ns = [](double s) { return kBase + static_cast<std::int64_t>(std::llround(s * 1e9)); };
  enum class Judge { kNow, kForHop };
  struct Run {
    std::vector<double> speeds;
    std::vector<std::int64_t> gps;  // per hop: the receive time of the fix it got, 0 for none
    int late = 0;
  };
  // `burst` s: how long the thread is held back between turns (0.1: every hop as it comes).
  const auto run = [&](double burst, Judge judge) {
    SynthesisStage stage;
    REQUIRE(stage.set_model(gearpulse::test::hatch_model(0.5)));
    gearpulse::GpsHistory history;
    Run out;
    int next_fix = 0, next_hop = 0;
    const int hops = static_cast<int>(2 * gearpulse::test::TownDrive::kCycle / 0.1);
    for (double turn = burst; next_hop < hops; turn += burst) {
      // The gpsd thread ran meanwhile: a report a second, 0.5 s after its moment, "no fix" in the outage.
      for (; next_fix <= turn; ++next_fix) {
        GpsReport r = fix(drive.at(std::max(next_fix - 0.5, 0.0)).speed, next_fix - 0.5);
        r.rx_ns = ns(next_fix);
        if (next_fix >= kLost && next_fix < kBack) r.mode = 1, r.speed = kNan;
        history.record(r);
      }
      // The thread steps every hop whose window the capture has given (the hop's time lags by 0.1 s).
      for (; next_hop < hops && next_hop * 0.1 + 0.1 <= turn + 1e-9; ++next_hop) {
        const double t = next_hop * 0.1;
        std::optional<GpsReport> gps = history.fresh(ns(turn), kTimeout);
        if (judge == Judge::kForHop) {
          const gearpulse::GpsHistory::ForHop h = history.for_hop(ns(t + kDue), ns(turn), kTimeout);
          gps = h.fix;
          out.late += h.late;
        }
        out.gps.push_back(gps ? gps->rx_ns : 0);
        out.speeds.push_back(stage.step(t, drive.at(t).freq, 30.0, true, gps, -10.0, 0.5).out.speed);
      }
    }
    return out;
  };
  const auto outage_m = [&](const Run& r) {
    double m = 0.0;
    for (std::size_t i = static_cast<std::size_t>(kLost / 0.1); i < static_cast<std::size_t>(kBack / 0.1);
         ++i)
      m += r.speeds[i] * 0.1;
    return m;
  };
  const auto differing = [](const auto& a, const auto& b) {
    REQUIRE(a.size() == b.size());
    std::size_t n = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
      n += a[i] != b[i];
    return n;
  };
  // On time: no hop is late, and every hop gets the GPS and gives the speed it gave judged now.
  const Run paced = run(0.1, Judge::kForHop);
  const Run paced_now = run(0.1, Judge::kNow);
  CHECK(paced.late == 0);
  CHECK(differing(paced.gps, paced_now.gps) == 0);
  CHECK(differing(paced.speeds, paced_now.speeds) == 0);
  // In 3 s bursts: judged now, the hops get newer fixes and the outage's distance moves by percents;
  // for_hop gives each late hop the fix of its due time, which a hop on time gets a tenth of a second
  // sooner at most (a report received in the hop before its due time: one hop a second, and a few at the
  // outage's edges, where the timeout is judged at the due time).
  const Run late = run(3.0, Judge::kForHop);
  const Run late_now = run(3.0, Judge::kNow);
  INFO("outage m: paced " << outage_m(paced) << ", in bursts " << outage_m(late) << ", judged now "
                          << outage_m(late_now));
  CHECK(late.late > 0);
  CHECK(differing(late.gps, paced.gps) <= late.gps.size() / 8);
  CHECK(std::abs(outage_m(late) - outage_m(paced)) < 0.002 * outage_m(paced));
  CHECK(differing(late_now.gps, paced.gps) > late.gps.size() / 2);
  CHECK(std::abs(outage_m(late_now) - outage_m(paced)) > 0.01 * outage_m(paced));
}
