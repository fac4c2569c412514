#include <catch2/catch.hpp>

#include <cmath>
#include <memory>
#include <vector>

#include "core/imm_speed_synth.hpp"
#include "tests/alloc_counter.hpp"
#include "tests/core/skip_downshift_drive.hpp"

using gearpulse::GearModel;
using gearpulse::ImmSpeedSynthesizer;
using gearpulse::kMissing;
using gearpulse::SpeedSource;
using gearpulse::SynthOutput;
using gearpulse::test::g_allocations;
using gearpulse::test::skip_downshift_outage;

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

TEST_CASE("imm synth: a skip downshift under braking as GPS is lost is followed, live and in replay alike") {
  ImmSpeedSynthesizer live_synth(hatch_model()), replay_synth(hatch_model());
  const double live = skip_downshift_outage(live_synth, kHatch, kIdle, true);
  const double replay = skip_downshift_outage(replay_synth, kHatch, kIdle, false);
  INFO("outage distance error: daemon's feed " << live << " %, a log's " << replay << " %");
  CHECK(std::abs(live) < 2.0);
  CHECK(std::abs(replay) < 2.0);
  CHECK(std::abs(live - replay) < 1.0);
}
