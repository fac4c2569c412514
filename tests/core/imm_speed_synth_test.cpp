#include <catch2/catch.hpp>

#include <cmath>
#include <memory>
#include <vector>

#include "core/imm_speed_synth.hpp"
#include "tests/alloc_counter.hpp"

using gearpulse::GearModel;
using gearpulse::ImmSpeedSynthesizer;
using gearpulse::kMissing;
using gearpulse::SpeedSource;
using gearpulse::SynthOutput;
using gearpulse::test::g_allocations;

namespace {

constexpr double kIdle = 13.3;                                           // Hz
const std::vector<double> kHatch = {0.125, 0.225, 0.347, 0.471, 0.574};  // (m/s)/Hz

std::shared_ptr<const GearModel> hatch_model() {
  auto m = std::make_shared<GearModel>();
  for (double t : kHatch)
    m->gears.push_back({t, 0.2, 0.0});
  m->sigma_speed = 0.1;
  m->sigma_freq = 0.3;
  m->extra["idle"] = {{"freq", kIdle}, {"sd", 0.4}, {"samples", 100}};
  return m;
}

// A drive at `dt` steps: 30 s at 50 km/h in 4th with GPS, then an outage of 40 s in which the car speeds up
// at 0.3 m/s^2 in 4th, shifts to 5th (0.5 s declutched) and holds its speed. Returns the distance the
// synthesis gives over the outage and the true one.
std::pair<double, double> outage_distance(double dt) {
  ImmSpeedSynthesizer synth(hatch_model());
  double v = 50.0 / 3.6, synth_distance = 0.0, true_distance = 0.0;
  for (double t = 0.0; t < 70.0 - 1e-9; t += dt) {
    const bool out = t >= 30.0;
    int gear = 4;
    if (t >= 30.0 && t < 50.0) v += 0.3 * dt;
    if (t >= 50.0) gear = t < 50.5 ? 0 : 5;
    const double f =
        gear > 0 ? v / kHatch[static_cast<std::size_t>(gear - 1)] : 0.5 * (v / kHatch[3] + kIdle);
    const SynthOutput o = synth.step(t, out ? kMissing : v, f);
    if (out) synth_distance += o.speed * dt, true_distance += v * dt;
  }
  return {synth_distance, true_distance};
}

constexpr double kStandingSpeed = ImmSpeedSynthesizer::kStanding;  // m/s

}  // namespace

TEST_CASE("imm synth: GPS passes through and the engaged gear is found") {
  ImmSpeedSynthesizer synth(hatch_model());
  SynthOutput o;
  for (int k = 0; k < 20; ++k)
    o = synth.step(k, 12.0, 12.0 / kHatch[2]);
  CHECK(o.source == SpeedSource::kGps);
  CHECK(o.speed == 12.0);
  CHECK(o.gear == 3);
  CHECK(synth.mode_probability(3) > 0.9);
}

TEST_CASE("imm synth: an outage follows the frequency in gear and through an upshift") {
  const auto [synth, truth] = outage_distance(0.1);
  CHECK(std::abs(synth - truth) / truth < 0.02);
}

TEST_CASE("imm synth: the outage distance does not depend on the step rate") {
  const double fine = outage_distance(0.1).first;
  const double coarse = outage_distance(1.0).first;
  const double sparse = outage_distance(2.0).first;
  CHECK(std::abs(coarse - fine) / fine < 0.02);
  CHECK(std::abs(sparse - fine) / fine < 0.03);
}

TEST_CASE("imm synth: a car braking to a stop at idle in an outage comes to rest") {
  ImmSpeedSynthesizer synth(hatch_model());
  double v = 40.0 / 3.6;
  SynthOutput o;
  for (double t = 0.0; t < 20.0; t += 0.5)
    o = synth.step(t, v, v / kHatch[3]);
  for (double t = 20.0; t < 60.0; t += 0.5) {
    v = std::max(0.0, v - 1.5 * 0.5);
    o = synth.step(t, kMissing, kIdle + 0.3 * std::sin(t));
  }
  CHECK(o.speed < kStandingSpeed);
  CHECK(o.gear == 0);
}

TEST_CASE("imm synth: step never allocates") {
  ImmSpeedSynthesizer synth(hatch_model());
  synth.step(0.0, 10.0, 10.0 / kHatch[2]);
  const auto before = g_allocations.load();
  for (int k = 1; k < 200; ++k)
    synth.step(0.1 * k, k < 100 ? 10.0 : kMissing, 10.0 / kHatch[2], k % 10 == 0);
  CHECK(g_allocations.load() == before);
}

TEST_CASE("imm synth: without a model an outage holds the last GPS speed") {
  ImmSpeedSynthesizer synth;
  synth.step(0.0, 12.5, 30.0);
  const SynthOutput o = synth.step(10.0, kMissing, 30.0);
  CHECK(o.speed == 12.5);
  CHECK(o.source == SpeedSource::kCoast);
}

namespace {

// Braking in 4th from 85 to 40 km/h at 3.2 m/s^2, 0.4 s declutched, then 2nd gear (a skip) just as GPS is
// lost, 60 s in 2nd at 24-34 km/h. The daemon's feed (the frequency every 0.1 s, a 1 Hz fix held for 1.5 s
// after it came, measured once) or a log's (rows every second). Returns the outage distance's error, %.
double skip_downshift_outage(bool daemon_feed) {
  ImmSpeedSynthesizer synth(hatch_model());
  constexpr double kBrake = 3.2, kFrom = 85.0 / 3.6, kTo = 40.0 / 3.6;
  constexpr double kBrakeStart = 60.0, kBrakeEnd = kBrakeStart + (kFrom - kTo) / kBrake;
  constexpr double kLost = kBrakeEnd + 0.4, kEnd = kLost + 60.0;
  const auto truth = [&](double t) -> std::pair<double, double> {  // speed, frequency
    if (t < kBrakeStart) return {kFrom, kFrom / kHatch[3]};
    if (t < kBrakeEnd) {
      const double v = kFrom - kBrake * (t - kBrakeStart);
      return {v, v / kHatch[3]};
    }
    if (t < kLost) {
      const double v = kTo - 0.3 * (t - kBrakeEnd);
      return {v, 0.5 * (v / kHatch[3] + kIdle)};
    }
    const double start = kTo - 0.3 * 0.4, cruise = (29.0 + 5.0 * std::sin((t - kLost) / 20.0 * 6.2832)) / 3.6;
    const double v = start + (cruise - start) * std::min(1.0, (t - kLost) / 5.0);
    return {v, v / kHatch[1]};
  };
  const double step = daemon_feed ? 0.1 : 1.0;
  double fix = kMissing, fix_t = -10.0, synthesized = 0.0, driven = 0.0;
  for (int k = 0; k * step < kEnd; ++k) {
    const double t = k * step;
    const auto [v, f] = truth(t);
    bool fresh = false;
    if (t < kLost && (!daemon_feed || k % 10 == 0)) fix = v, fix_t = t, fresh = true;
    const double held = daemon_feed ? 1.5 : 0.0;  // the daemon's GPS timeout
    const double gps = t < kLost || t - fix_t < held ? fix : kMissing;
    const SynthOutput o = synth.step(t, gps, f, fresh);
    if (t >= kLost) synthesized += o.speed * step, driven += v * step;
  }
  return 100.0 * (synthesized - driven) / driven;
}

}  // namespace

TEST_CASE("imm synth: a skip downshift under braking as GPS is lost is followed, live and in replay alike") {
  const double live = skip_downshift_outage(true);
  const double replay = skip_downshift_outage(false);
  INFO("outage distance error: daemon's feed " << live << " %, a log's " << replay << " %");
  CHECK(std::abs(live) < 2.0);
  CHECK(std::abs(replay) < 2.0);
  CHECK(std::abs(live - replay) < 1.0);
}
