#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <new>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "bench/outage_protocol.hpp"
#include "core/speed_synth.hpp"
#include "tests/alloc_counter.hpp"
#include "tests/core/skip_downshift_drive.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::GearModel;
using gearpulse::kMissing;
using gearpulse::SpeedSource;
using gearpulse::SpeedSynthesizer;
using gearpulse::SynthOutput;

using gearpulse::test::g_allocations;
using gearpulse::test::skip_downshift_outage;

namespace {

constexpr double kKmh = 1.0 / 3.6;
constexpr double kIdle = 13.3;  // Hz

std::shared_ptr<const GearModel> model_of(const std::vector<double>& theta, double scale = 1.0) {
  auto m = std::make_shared<GearModel>();
  for (double t : theta)
    m->gears.push_back({t * scale, 1.0 / static_cast<double>(theta.size()), 0.0});
  m->sigma_speed = 0.1;
  m->sigma_freq = 0.3;
  m->outlier_weight = 0.1;
  return m;
}

const std::vector<double> kHatch = {0.125, 0.225, 0.347, 0.471, 0.574};  // Etios-like, (m/s)/Hz

// A scripted drive at 1 Hz: each phase holds a gear (0 = declutched at idle) and an acceleration.
struct Phase {
  int gear;
  double accel;  // m/s^2
  double seconds;
};
struct Row {
  double t, speed, freq;
  int gear;
};
std::vector<Row> script(double v0, const std::vector<Phase>& phases, const std::vector<double>& theta) {
  std::vector<Row> rows;
  double t = 0.0, v = v0;
  for (const Phase& p : phases) {
    for (int k = 0; k < static_cast<int>(p.seconds); ++k) {
      v = std::max(0.0, v + p.accel);
      const double f = p.gear > 0 ? v / theta[static_cast<std::size_t>(p.gear - 1)] : kIdle;
      rows.push_back({t, v, f, p.gear});
      t += 1.0;
    }
  }
  return rows;
}

// A car standing at a light as an OBD logger polling every 2 s sees it: `count` rows (at most 11) from
// t = 0, speed 0, the idle wandering as a real one does.
std::vector<Row> standing_polled_every_2s(int count) {
  constexpr double kIdleWander[] = {13.0, 12.6, 12.1, 11.6, 11.4, 13.1, 13.6, 14.3, 11.8, 12.8, 13.0};
  std::vector<Row> rows;
  for (int k = 0; k < count && k < static_cast<int>(std::size(kIdleWander)); ++k)
    rows.push_back({2.0 * k, 0.0, kIdleWander[k], 0});
  return rows;
}

// Feeds rows with GPS up to `outage_from` (s), engine frequency only afterwards.
std::vector<SynthOutput> replay(SpeedSynthesizer& synth, const std::vector<Row>& rows, double outage_from) {
  std::vector<SynthOutput> out;
  for (const Row& r : rows)
    out.push_back(synth.step(r.t, r.t < outage_from ? r.speed : kMissing, r.freq));
  return out;
}

// 20 s standing at idle, then the scripted drive (script()) with the engine held at `rolling_idle` whenever
// the car is out of gear, as many engines are held above their standing idle while the car rolls.
std::vector<Row> stand_then_drive_rolling_at(double rolling_idle, const std::vector<Phase>& phases) {
  constexpr int kStanding = 20;  // s
  std::vector<Row> rows;
  for (int k = 0; k < kStanding; ++k)
    rows.push_back({static_cast<double>(k), 0.0, kIdle, 0});
  for (Row r : script(0.0, phases, kHatch)) {
    r.t += kStanding;
    if (r.gear == 0) r.freq = rolling_idle;
    rows.push_back(r);
  }
  return rows;
}

// The model fitted for a drive recorded from the simulator (tests/core/data/NAME_model.json).
std::shared_ptr<GearModel> recorded_model(const std::string& name) {
  std::ifstream model_file(GEARPULSE_SOURCE_DIR "/tests/core/data/" + name + "_model.json");
  std::stringstream model_text;
  model_text << model_file.rdbuf();
  return std::make_shared<GearModel>(gearpulse::parse_model(model_text.str()));
}

// Steps `synth` through a drive recorded from the simulator at RATE ("10hz", "1hz"; tests/core/data/
// NAME_RATE.csv: t, GPS speed or blank, frequency, true speed), calling check(t, true speed, output) after
// every row.
template <class Check>
void replay_rows(const std::string& name, const std::string& rate, SpeedSynthesizer& synth, Check check) {
  std::ifstream rows(GEARPULSE_SOURCE_DIR "/tests/core/data/" + name + "_" + rate + ".csv");
  REQUIRE(rows);
  std::string line;
  while (std::getline(rows, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells(1);
    for (char c : line)
      if (c == ',')
        cells.emplace_back();
      else
        cells.back().push_back(c);
    REQUIRE(cells.size() == 4);
    const double t = std::stod(cells[0]), freq = std::stod(cells[2]), truth = std::stod(cells[3]);
    const double gps = cells[1].empty() ? kMissing : std::stod(cells[1]);
    check(t, truth, synth.step(t, gps, freq));
  }
}

// The same through a fresh synthesizer with the model fitted for the drive.
template <class Check>
void replay_recording(const std::string& name, const std::string& rate, Check check) {
  SpeedSynthesizer synth(recorded_model(name));
  replay_rows(name, rate, synth, check);
}

// Replays a recording (replay_recording; 10 Hz unless `rate` says otherwise) and checks the synthesized
// speed against the true one for every row from `from` to `to` s; returns how many rows were checked.
int speed_within(const std::string& name, double from, double to, double tolerance,
                 const std::string& rate = "10hz") {
  int checked = 0;
  replay_recording(name, rate, [&](double t, double truth, const SynthOutput& out) {
    if (t < from || t > to) return;
    INFO("t = " << t << " s: truth " << truth * 3.6 << " km/h, synthesized " << out.speed * 3.6 << " in gear "
                << out.gear);
    CHECK(std::abs(out.speed - truth) < tolerance);
    ++checked;
  });
  return checked;
}

}  // namespace

TEST_CASE("synth: without a model GPS passes through and an outage holds its last speed, then stops") {
  SpeedSynthesizer synth;
  // No GPS yet: nothing is known.
  SynthOutput o = synth.step(0.0, kMissing, 40.0);
  CHECK(o.source == SpeedSource::kNone);
  CHECK(o.speed == 0.0);
  CHECK(gearpulse::source_name(o.source) == "none");
  o = synth.step(1.0, 12.5, 40.0);
  CHECK(o.source == SpeedSource::kGps);
  CHECK(o.speed == 12.5);
  CHECK(o.gear == 0);
  // The frequency says nothing of the speed without a ladder: a tunnel is driven at the speed going in...
  const double hold = gearpulse::SynthTuning{}.hold_time;
  o = synth.step(2.0, kMissing, 80.0);
  CHECK(o.source == SpeedSource::kCoast);
  CHECK(o.speed == 12.5);
  CHECK(synth.step(1.0 + hold, kMissing, 20.0).speed == 12.5);
  // ... and a long outage most likely ends parked: down to rest at the coasting deceleration.
  o = synth.step(1.0 + hold + 5.0, kMissing, 20.0);
  CHECK(o.speed == Approx(12.5 + 5.0 * gearpulse::SynthTuning{}.coast_accel));
  o = synth.step(1.0 + hold + 60.0, kMissing, 20.0);
  CHECK(o.speed == 0.0);
  CHECK(o.source == SpeedSource::kCoast);

  // A model without gears (an automatic, a CVT) alike.
  SpeedSynthesizer empty(std::make_shared<const GearModel>());
  CHECK(empty.step(0.0, 3.0, 20.0).source == SpeedSource::kGps);
  o = empty.step(1.0, kMissing, 20.0);
  CHECK(o.source == SpeedSource::kCoast);
  CHECK(o.speed == 3.0);
}

TEST_CASE("synth: tracks the gear while GPS is present") {
  SpeedSynthesizer synth(model_of(kHatch));
  const auto rows = script(0.0, {{0, 0.0, 10}, {1, 1.5, 4}, {2, 1.0, 6}, {3, 0.5, 10}}, kHatch);
  const auto out = replay(synth, rows, 1e9);
  CHECK(out[5].gear == 0);  // standing
  CHECK(out[12].gear == 1);
  CHECK(out.back().gear == 3);
  CHECK(out.back().source == SpeedSource::kGps);
  CHECK(synth.idle_freq() == Approx(kIdle));
}

TEST_CASE("synth: keeps the gear and follows the frequency through an outage") {
  SpeedSynthesizer synth(model_of(kHatch));
  const auto rows = script(
      0.0, {{0, 0.0, 10}, {1, 1.5, 4}, {2, 1.0, 6}, {3, 0.4, 10}, {3, -0.3, 20}, {3, 0.2, 20}}, kHatch);
  const auto out = replay(synth, rows, 35.0);
  for (std::size_t i = 36; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].source == SpeedSource::kEngine);
    CHECK(out[i].gear == 3);
    CHECK(out[i].speed == Approx(rows[i].speed).margin(0.5 * kKmh));
  }
}

TEST_CASE("synth: the belief's spread is none under GPS, small in a gear, larger coasting declutched") {
  SpeedSynthesizer synth(model_of(kHatch));
  // GPS lost at 30 s cruising in 3rd; braking in gear, then declutched at idle and braking to a stop.
  const auto rows = script(
      0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.3, 15}, {3, -1.0, 5}, {0, -1.5, 10}, {0, 0.0, 20}},
      kHatch);
  const auto out = replay(synth, rows, 30.0);
  for (std::size_t i = 0; i < 30; ++i)
    CHECK(out[i].speed_sd == 0.0);
  const std::size_t declutch = 8 + 3 + 8 + 15 + 5;
  double in_gear = 0.0, coasting = 0.0;
  for (std::size_t i = 32; i < declutch; ++i)
    in_gear = std::max(in_gear, out[i].speed_sd);
  for (std::size_t i = declutch + 1; i < declutch + 4; ++i)
    coasting = std::max(coasting, out[i].speed_sd);
  INFO("spread in gear " << in_gear << " m/s, coasting " << coasting << " m/s");
  CHECK(in_gear > 0.0);
  CHECK(in_gear < 0.5);
  CHECK(coasting > 2.0 * in_gear);
}

TEST_CASE("synth: follows up- and downshifts inside an outage") {
  SpeedSynthesizer synth(model_of(kHatch));
  // Outage from 20 s: 2nd -> 3rd -> 4th while accelerating, then back down to 3rd while slowing.
  const auto rows = script(0.0,
                           {{0, 0.0, 8},
                            {1, 1.8, 3},
                            {2, 1.2, 12},
                            {3, 0.8, 10},
                            {4, 0.4, 15},
                            {4, -0.8, 8},
                            {3, -0.5, 10},
                            {3, 0.0, 10}},
                           kHatch);
  const auto out = replay(synth, rows, 20.0);
  int right = 0, total = 0;
  double worst = 0.0;
  for (std::size_t i = 20; i < rows.size(); ++i) {
    ++total;
    right += out[i].gear == rows[i].gear;
    worst = std::max(worst, std::abs(out[i].speed - rows[i].speed));
  }
  CHECK(right >= total - 3);  // a shift may be recognised one sample late
  CHECK(worst < 12.0 * kKmh);
  CHECK(out.back().gear == 3);
  CHECK(out.back().speed == Approx(rows.back().speed).margin(1.0 * kKmh));
}

TEST_CASE("synth: coasts through clutch-out and comes to zero at a stop") {
  SpeedSynthesizer synth(model_of(kHatch));
  // Drive, GPS lost at 30 s in 3rd, brake in gear, declutch at idle, stand for 20 s at the light.
  const auto rows = script(
      0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.3, 15}, {3, -1.0, 5}, {0, -1.5, 10}, {0, 0.0, 20}},
      kHatch);
  const auto out = replay(synth, rows, 30.0);
  const std::size_t declutch = 8 + 3 + 8 + 15 + 5;
  bool coasted = false;
  for (std::size_t i = declutch; i < declutch + 6; ++i)
    coasted = coasted || out[i].source == SpeedSource::kCoast;
  CHECK(coasted);
  REQUIRE(rows[declutch + 10].speed == 0.0);
  // Declutched at idle the estimate only ever falls (no gear hypothesis lifts it again), and it reaches
  // zero while the car still waits at the light: without GPS the firmness of the braking is unknown.
  for (std::size_t i = declutch + 1; i < rows.size(); ++i)
    CHECK(out[i].speed <= out[i - 1].speed + 1e-9);
  for (std::size_t i = declutch + 20; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].speed == 0.0);
    CHECK(out[i].gear == 0);
    CHECK(out[i].source == SpeedSource::kCoast);
  }
  // Never faster than the car was, never negative.
  for (std::size_t i = 30; i < rows.size(); ++i)
    CHECK(out[i].speed >= 0.0);
}

TEST_CASE("synth: a frequency no gear explains is coasted through") {
  SpeedSynthesizer synth(model_of(kHatch));
  auto rows = script(0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.0, 20}}, kHatch);
  const double v = rows.back().speed;
  // Clutch pressed with a blip of throttle: revs far above any gear's, or the tone lost entirely.
  rows.push_back({rows.back().t + 1, v, 95.0, 0});
  rows.push_back({rows.back().t + 1, v, kMissing, 0});
  rows.push_back({rows.back().t + 1, v, v / kHatch[2], 3});
  const auto out = replay(synth, rows, 30.0);
  const std::size_t n = rows.size();
  CHECK(out[n - 3].source == SpeedSource::kCoast);
  CHECK(out[n - 2].source == SpeedSource::kCoast);
  CHECK(out[n - 3].speed < v);
  CHECK(out[n - 3].speed > v - 1.0);  // gentle: a shift does not stop the car
  CHECK(out[n - 1].gear == 3);
  CHECK(out[n - 1].speed == Approx(v).margin(1.0 * kKmh));
}

TEST_CASE("synth: a model swap mid-outage keeps the output continuous") {
  SpeedSynthesizer synth(model_of(kHatch));
  const auto rows = script(0.0, {{0, 0.0, 8}, {1, 1.8, 3}, {2, 1.2, 8}, {3, 0.0, 30}}, kHatch);
  std::vector<SynthOutput> out;
  for (const Row& r : rows) {
    if (r.t == 40.0) {
      CHECK(synth.set_model(model_of(kHatch, 1.004)));  // retrained: thetas moved by 0.4 %
    }
    if (r.t == 45.0) {
      CHECK(synth.set_model(model_of({0.2, 0.35, 0.47, 0.58})));  // a different ladder
    }
    out.push_back(synth.step(r.t, r.t < 30.0 ? r.speed : kMissing, r.freq));
  }
  CHECK(out[40].gear == 3);
  CHECK(std::abs(out[40].speed - out[39].speed) < 0.01 * out[39].speed);
  CHECK(std::abs(out[45].speed - out[44].speed) < 0.05 * out[44].speed);
  CHECK(out[45].source == SpeedSource::kEngine);

  // Dropping the model: an outage then holds the last GPS speed (from 29 s, 71 s ago: coming to rest),
  // GPS still passes.
  synth.set_model(nullptr);
  const SynthOutput dropped = synth.step(100.0, kMissing, 30.0);
  CHECK(dropped.source == SpeedSource::kCoast);
  CHECK(dropped.speed < out[29].speed);
  CHECK(synth.step(101.0, 5.0, 30.0).source == SpeedSource::kGps);
  // More gears than the fixed capacity: refused, the old model stays.
  std::vector<double> many;
  for (int i = 0; i < SpeedSynthesizer::kMaxGears + 1; ++i)
    many.push_back(0.05 * (i + 1));
  CHECK_FALSE(synth.set_model(model_of(many)));
  CHECK(synth.model() == nullptr);
}

TEST_CASE("synth: step never allocates") {
  auto vehicle = gearpulse::sim::vehicle_preset("hatch-5");
  const auto drive = gearpulse::sim::simulate_drive(vehicle, {.duration = 600.0, .seed = 3});
  const auto samples = gearpulse::sim::to_samples(gearpulse::sim::observe(drive, {.seed = 4}));
  SpeedSynthesizer synth(model_of(vehicle.theta));
  // The replacement carries what a fit records beyond the ratios (idle, revs per gear): loading it
  // allocates nothing either.
  auto replacement = std::make_shared<GearModel>(*model_of(vehicle.theta, 1.01));
  replacement->extra["idle"] = {{"freq", vehicle.idle_freq}, {"sd", 0.3}, {"samples", 100}};
  replacement->extra["revs"] = nlohmann::json::array();
  for (std::size_t g = 0; g < vehicle.theta.size(); ++g)
    replacement->extra["revs"].push_back({{"mean_log", 3.3}, {"sd_log", 0.25}, {"samples", 100}});
  const long before = g_allocations.load();
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const auto& s = samples[i];
    const bool outage = (i / 60) % 2 == 1;
    (void)synth.step(s.t, outage ? kMissing : s.speed, s.freq);
    if (i == samples.size() / 2) synth.set_model(replacement);
  }
  CHECK(g_allocations.load() == before);
  static_assert(noexcept(synth.step(0.0, 0.0, 0.0)));
  // Nor does a ladder that gains a gear measured under GPS (the model lacks the car's third gear), or a
  // model swapped in beside it.
  std::vector<double> lacking = vehicle.theta;
  lacking.erase(lacking.begin() + 2);
  SpeedSynthesizer young(model_of(lacking));
  auto young_replacement = std::make_shared<GearModel>(*model_of(lacking, 1.01));
  young_replacement->extra = replacement->extra;
  young_replacement->extra["revs"].erase(2);
  int in_seen_gear = 0;
  const long young_before = g_allocations.load();
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const auto& s = samples[i];
    const bool outage = (i / 60) % 2 == 1;
    const SynthOutput out = young.step(s.t, outage ? kMissing : s.speed, s.freq);
    in_seen_gear += out.source == SpeedSource::kEngine && out.gear == 0 ? 1 : 0;
    if (i == samples.size() / 2) young.set_model(young_replacement);
  }
  CHECK(g_allocations.load() == young_before);
  CHECK(in_seen_gear > 0);
}

TEST_CASE("synth: a step it cannot take after a swap to a shorter ladder names no gear the ladder lacks") {
  SpeedSynthesizer synth(model_of(kHatch));
  for (int k = 0; k < 30; ++k)
    synth.step(k, 20.0, 20.0 / kHatch[4]);  // fifth gear
  REQUIRE(synth.last().gear == 5);
  REQUIRE(synth.set_model(model_of({0.125, 0.225, 0.347})));
  const SynthOutput o = synth.step(std::numeric_limits<double>::quiet_NaN(), 20.0, 50.0);
  CHECK(o.gear <= 3);
}

TEST_CASE("synth: bad input never produces a bad output") {
  SpeedSynthesizer synth(model_of(kHatch));
  const double nan = kMissing, inf = std::numeric_limits<double>::infinity();
  const double inputs[][3] = {{0, 10, 30},   {1, nan, nan},  {nan, 5, 5}, {0.5, -3, 30},      {2, inf, -5},
                              {2, nan, inf}, {1e9, nan, 40}, {1e9, 0, 0}, {1e9 + 1, nan, 1e6}};
  for (const auto& in : inputs) {
    const SynthOutput o = synth.step(in[0], in[1], in[2]);
    CHECK(std::isfinite(o.speed));
    CHECK(o.speed >= 0.0);
    CHECK(o.gear >= 0);
    CHECK(o.gear <= 5);
  }
}

TEST_CASE("synth: whatever the input, an outage never outruns what GPS or the engine last showed") {
  // Random segments of GPS present or lost, and of a frequency that fits a gear, idles, jumps about
  // anywhere in the band or is lost, at 1 and 10 steps per second. Through an outage the output can
  // come only from the last GPS speed (coasting never gains) or from a gear's theta x a frequency seen
  // since: it must never exceed the larger of the two by more than a car gains in a few seconds.
  const double rate = GENERATE(1.0, 10.0);
  INFO("steps per second " << rate);
  const auto model = model_of(kHatch);
  const double theta_top = kHatch.back();
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int violations = 0;
  double worst = 0.0;
  for (int drive = 0; drive < 40; ++drive) {
    SpeedSynthesizer synth(model);
    double t = 0.0, v = 0.0, last_gps = 0.0, top_freq = 0.0;
    for (int segment = 0; segment < 20; ++segment) {
      const bool gps = u(rng) < 0.5;
      const int kind = static_cast<int>(u(rng) * 4.0);  // 0 in gear, 1 idle, 2 anywhere, 3 lost
      const int gear = static_cast<int>(u(rng) * static_cast<double>(kHatch.size()));
      const double accel = (u(rng) - 0.5) * 3.0;
      const int steps = static_cast<int>((1.0 + u(rng) * 19.0) * rate);
      for (int k = 0; k < steps; ++k) {
        t += 1.0 / rate;
        v = std::clamp(v + accel / rate, 0.0, 40.0);
        double freq = kMissing;
        if (kind == 0) freq = v / kHatch[static_cast<std::size_t>(gear)];
        if (kind == 1) freq = kIdle * (0.95 + 0.1 * u(rng));
        if (kind == 2) freq = 10.0 + 90.0 * u(rng);
        const SynthOutput o = synth.step(t, gps ? v : kMissing, freq);
        REQUIRE(std::isfinite(o.speed));
        REQUIRE(o.speed >= 0.0);
        if (gps) {
          last_gps = v;
          top_freq = 0.0;
          continue;
        }
        if (std::isfinite(freq)) top_freq = std::max(top_freq, freq);
        const double bound = std::max(last_gps, theta_top * top_freq) + 3.0;
        if (o.speed > bound) {
          ++violations;
          worst = std::max(worst, o.speed - bound);
        }
      }
    }
  }
  INFO("outage outputs beyond the bound: " << violations << ", worst by " << worst << " m/s");
  CHECK(violations == 0);
}

namespace {

// |error| km/h of every outage sample of a simulated drive observed every `period` s (outages of 60 s
// from 120 s in, then every 180 s: the benches' protocol, bench/outage_protocol.hpp). With a fix
// interval, GPS gives a fix only every so many seconds, and every step until the next one is given it
// again, as the daemon gives the newest fresh fix at every tracker hop (flagged new at the first).
std::vector<double> outage_errors(const gearpulse::sim::Drive& drive, double period, std::uint64_t seed,
                                  double fix_interval = 0.0) {
  gearpulse::sim::ObservationOptions obs;
  obs.period = period;
  obs.seed = seed;
  SpeedSynthesizer synth(model_of(drive.vehicle.theta));
  std::vector<double> errors;
  double fix = kMissing;
  long fix_index = -1;
  for (const auto& r : gearpulse::sim::observe(drive, obs)) {
    const double t = r.truth.t;
    const bool out = gearpulse::bench::in_outage(t);
    double gps = out ? kMissing : r.speed;
    bool fresh = true;
    if (fix_interval > 0.0) {
      const long index = std::lround(std::floor(t / fix_interval + 1e-6));
      fresh = !out && index != fix_index;
      if (fresh) {
        fix = r.speed;
        fix_index = index;
      }
      if (!out) gps = fix;
    }
    const SynthOutput o = synth.step(t, gps, r.freq, fresh);
    if (out) errors.push_back(std::abs(o.speed - r.truth.speed) / kKmh);
  }
  return errors;
}

using gearpulse::bench::quantile;

// Calls f(drive, seed) for each of eight simulated 15-minute drives at 10 Hz (two cars, mixed and urban).
template <class F>
void for_each_test_drive(F f) {
  for (const char* name : {"hatch-5", "close-6"}) {
    for (const auto style : {gearpulse::sim::DrivingStyle::kMixed, gearpulse::sim::DrivingStyle::kUrban}) {
      for (const std::uint64_t seed : {7, 8})
        f(gearpulse::sim::simulate_drive(gearpulse::sim::vehicle_preset(name),
                                         {.style = style, .duration = 900.0, .dt = 0.1, .seed = seed}),
          seed);
    }
  }
}

// Share of the errors over `km_h`.
double share_beyond(const std::vector<double>& e, double km_h) {
  return static_cast<double>(std::count_if(e.begin(), e.end(), [&](double x) { return x > km_h; })) /
         static_cast<double>(e.size());
}

}  // namespace

// A tracker that never locks (no ripple on this car's supply) while GPS shows a steady cruise, then GPS lost
// too: nothing says the car keeps its speed. The declutched mode held the belief under GPS (every gear
// fades without revs) and learned the cruise as its deceleration, zero, so the output stayed at the last
// GPS speed for good: 390 s at 72 km/h, 7.8 km of pulses for a car that may have stopped.
TEST_CASE("synth: with neither GPS nor engine frequency the speed is not held for good") {
  SpeedSynthesizer synth(model_of(kHatch));
  for (int k = 0; k <= 10; ++k)
    synth.step(k, 20.0, kMissing);
  double last = 20.0;
  for (int k = 11; k <= 400; ++k) {
    const SynthOutput o = synth.step(k, kMissing, kMissing);
    REQUIRE(o.speed <= last + 1e-9);  // never gaining speed
    last = o.speed;
  }
  CHECK(last == 0.0);
}

// The same with the engine seen under GPS, declutched a few seconds at a steady speed before the cruise
// went on in fifth: those fixes taught the clutch a deceleration of zero, which alone made the car roll on
// at 72 km/h for good once the revs and GPS were both lost.
TEST_CASE("synth: a few steady fixes declutched do not make the car roll on for good") {
  SpeedSynthesizer synth(model_of(kHatch));
  const double v = 20.0, fifth = v / kHatch[4];
  int k = 0;
  for (; k < 30; ++k)
    synth.step(k, v, fifth);
  for (; k < 34; ++k)
    synth.step(k, v, kIdle);
  for (; k < 90; ++k)
    synth.step(k, v, fifth);
  double last = v;
  for (; k < 400; ++k) {
    const SynthOutput o = synth.step(k, kMissing, kMissing);
    REQUIRE(o.speed <= last + 1e-9);
    last = o.speed;
  }
  CHECK(last == 0.0);
}

TEST_CASE("synth: outage speeds do not depend on the step rate") {
  // The same drives, observed at 1 Hz (GPS, logs) and at 10 Hz (the tracker's hops): the filter's motion,
  // mode changes and evidence are per second, so both rates give about the same speeds.
  std::vector<double> slow, fast;
  for_each_test_drive([&](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
    const auto one = outage_errors(drive, 1.0, seed + 4), ten = outage_errors(drive, 0.1, seed + 4);
    slow.insert(slow.end(), one.begin(), one.end());
    fast.insert(fast.end(), ten.begin(), ten.end());
  });
  const auto beyond = share_beyond;
  INFO("1 Hz median " << quantile(slow, 0.5) << " km/h, " << 100.0 * beyond(slow, 10.0)
                      << " % beyond 10 km/h; 10 Hz " << quantile(fast, 0.5) << ", "
                      << 100.0 * beyond(fast, 10.0) << " %");
  CHECK(quantile(slow, 0.5) < 1.0);
  CHECK(quantile(fast, 0.5) < 1.0);
  CHECK(beyond(fast, 10.0) < 2.0 * beyond(slow, 10.0) + 0.03);
}

TEST_CASE("synth: at 10 Hz hops given a 1 Hz fix at each, outages are followed as with a fix at every hop") {
  // The daemon steps the synthesis at every tracker hop and gives it the newest fresh fix each time: one a
  // second from most receivers, so ten steps see the same fix. Measured again at each, a fix held the speed
  // to a value up to a second old, and the deceleration learned declutched came out at a fraction of the
  // car's.
  std::vector<double> every, held;
  for_each_test_drive([&](const gearpulse::sim::Drive& drive, std::uint64_t seed) {
    const auto a = outage_errors(drive, 0.1, seed + 4), b = outage_errors(drive, 0.1, seed + 4, 1.0);
    every.insert(every.end(), a.begin(), a.end());
    held.insert(held.end(), b.begin(), b.end());
  });
  const auto beyond = share_beyond;
  INFO("a fix at every hop: median " << quantile(every, 0.5) << " km/h, p95 " << quantile(every, 0.95) << ", "
                                     << 100.0 * beyond(every, 5.0)
                                     << " % beyond 5 km/h; a 1 Hz fix held: " << quantile(held, 0.5) << ", "
                                     << quantile(held, 0.95) << ", " << 100.0 * beyond(held, 5.0) << " %");
  CHECK(quantile(held, 0.5) < 1.0);
  CHECK(beyond(held, 5.0) < 1.2 * beyond(every, 5.0) + 0.005);
  CHECK(quantile(held, 0.95) < 1.2 * quantile(every, 0.95) + 0.3);
}

TEST_CASE("synth: knows the idle from the model before GPS has shown the car standing") {
  // GPS from a rolling start (the daemon restarted on the move), lost in 3rd; the car brakes in gear,
  // declutches and waits at idle. The idle the fit saw tells the wait from a high gear at low revs.
  auto model = std::make_shared<GearModel>(*model_of(kHatch));
  model->extra["idle"] = {{"freq", kIdle}, {"sd", 0.3}, {"samples", 500}};
  SpeedSynthesizer synth(model);
  const auto rows = script(8.0, {{3, 0.3, 20}, {3, -1.0, 5}, {0, -1.5, 6}, {0, 0.0, 40}}, kHatch);
  const auto out = replay(synth, rows, 15.0);
  CHECK(std::isnan(SpeedSynthesizer(model_of(kHatch)).idle_freq()));
  CHECK(synth.idle_freq() == Approx(kIdle));
  for (std::size_t i = rows.size() - 20; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].speed == 0.0);
    CHECK(out[i].gear == 0);
  }
}

TEST_CASE("synth: the idle follows a warming engine down sooner than a blip up") {
  SpeedSynthesizer synth(model_of(kHatch));
  double t = 0.0;
  for (; t < 60.0; t += 1.0)  // a cold engine idles high at the light
    synth.step(t, 0.0, 20.0);
  REQUIRE(synth.idle_freq() == Approx(20.0));
  for (; t < 90.0; t += 1.0)  // warm now, at the next light
    synth.step(t, 0.0, kIdle);
  CHECK(synth.idle_freq() < kIdle + 1.0);
  for (; t < 300.0; t += 1.0)
    synth.step(t, 0.0, kIdle);
  const double settled = synth.idle_freq();
  for (; t < 330.0; t += 1.0)  // the air conditioning kicks in for half a minute
    synth.step(t, 0.0, kIdle + 2.0);
  CHECK(synth.idle_freq() - settled < 1.5);
}

TEST_CASE("synth: a warming engine's idle is followed down while the car coasts, with no stop to show it") {
  // A cold start idles high while the car stands; the drive then never stops, but the driver coasts
  // declutched at the warm idle under GPS. Then GPS is lost and the car coasts again: the engine at warm
  // idle is a car rolling out of gear, not a high gear lugging at walking pace.
  constexpr double kColdIdle = 20.0;
  std::vector<Row> rows;
  for (int k = 0; k < 30; ++k)
    rows.push_back({static_cast<double>(k), 0.0, kColdIdle, 0});
  const auto drive = script(0.0,
                            {{1, 1.8, 3},
                             {2, 1.2, 8},
                             {3, 0.5, 15},
                             {4, 0.2, 20},
                             {0, -0.3, 25},
                             {3, 0.3, 20},
                             {4, 0.1, 20},
                             {0, -0.3, 25},
                             {4, 0.3, 20},
                             {0, -0.3, 20}},
                            kHatch);
  for (Row r : drive) {
    r.t += 30.0;
    rows.push_back(r);
  }
  SpeedSynthesizer synth(model_of(kHatch));
  const double outage_from = rows[rows.size() - 25].t;
  const auto out = replay(synth, rows, outage_from);
  CHECK(synth.idle_freq() < 0.5 * (kColdIdle + kIdle));
  // The last 20 s coast declutched inside the outage: no gear, and the speed of a car rolling out of gear
  // (4th gear at idle revs would be 6 m/s).
  for (std::size_t i = rows.size() - 15; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t << ", truth " << rows[i].speed << " m/s, synthesized " << out[i].speed);
    CHECK(out[i].gear == 0);
    CHECK(std::abs(out[i].speed - rows[i].speed) < 4.0);
  }
}

TEST_CASE("synth: rolling declutched at revs held above the standing idle is coasting, not a gear lugging") {
  // Many engines are held above their standing idle while the car rolls declutched, the revs flat while
  // the car slows. GPS shows the car standing at idle, then twice rolling out of gear at those raised revs;
  // then GPS is lost and the car rolls out of gear again from 4th. That is a car coasting, not 4th (7.5 m/s)
  // or 3rd (5.6 m/s) lugging at a steady speed.
  const auto rows = stand_then_drive_rolling_at(1.2 * kIdle, {{1, 1.8, 3},
                                                              {2, 1.2, 8},
                                                              {3, 0.5, 15},
                                                              {4, 0.2, 20},
                                                              {0, -0.4, 15},
                                                              {3, 0.3, 20},
                                                              {4, 0.1, 20},
                                                              {0, -0.4, 15},
                                                              {4, 0.3, 20},
                                                              {0, -0.4, 20}});
  SpeedSynthesizer synth(model_of(kHatch));
  const double outage_from = rows[rows.size() - 20].t;
  const auto out = replay(synth, rows, outage_from);
  for (std::size_t i = rows.size() - 18; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t << ", truth " << rows[i].speed << " m/s, synthesized " << out[i].speed
                << " in gear " << out[i].gear);
    CHECK(out[i].gear == 0);
    CHECK(std::abs(out[i].speed - rows[i].speed) < 3.0);
  }
}

TEST_CASE("synth: the rolling idle the fit recorded counts before GPS has shown the car rolling") {
  // As above, but GPS never shows the car rolling out of gear before it is lost: the fit's rolling idle
  // (model extra.rolling_idle) tells the coast from 4th gear lugging.
  constexpr double kRollingIdle = 1.2 * kIdle;
  auto model = std::make_shared<GearModel>(*model_of(kHatch));
  model->extra["rolling_idle"] = {{"freq", kRollingIdle}, {"samples", 200}};
  const auto rows = stand_then_drive_rolling_at(
      kRollingIdle, {{1, 1.8, 3}, {2, 1.2, 8}, {3, 0.5, 15}, {4, 0.2, 20}, {4, 0.3, 20}, {0, -0.4, 20}});
  for (const bool with_prior : {true, false}) {
    SpeedSynthesizer synth(with_prior ? model : model_of(kHatch));
    const auto out = replay(synth, rows, rows[rows.size() - 20].t);
    int coasting = 0;
    for (std::size_t i = rows.size() - 18; i < rows.size(); ++i) {
      INFO("t = " << rows[i].t << ", truth " << rows[i].speed << " m/s, synthesized " << out[i].speed
                  << " in gear " << out[i].gear);
      coasting += out[i].gear == 0 && std::abs(out[i].speed - rows[i].speed) < 3.0 ? 1 : 0;
    }
    INFO((with_prior ? "with" : "without") << " the fit's rolling idle: " << coasting << " of 18 coasting");
    if (with_prior)
      CHECK(coasting == 18);
    else
      CHECK(coasting < 18);  // the test's premise: without it, the revs look like a gear
  }
}

TEST_CASE("synth: a stop in an outage is seen while the idle still falls from a cold start") {
  // The car waits at a light with the engine still cold (GPS shows the high idle), drives off, loses GPS in
  // 5th, brakes in gear, declutches and stands at the next light. The engine is warmer by then: its idle lies
  // between the one GPS showed and the warm idle the fit recorded. That is a car at rest, not first gear
  // creeping at walking pace.
  constexpr double kColdIdle = 17.0, kWarmerIdle = 14.5;
  auto model = std::make_shared<GearModel>(*model_of(kHatch));
  model->extra["idle"] = {{"freq", kIdle}, {"sd", 0.3}, {"samples", 500}};
  std::vector<Row> rows;
  for (int k = 0; k < 30; ++k)
    rows.push_back({static_cast<double>(k), 0.0, kColdIdle, 0});
  const auto drive = script(0.0,
                            {{1, 1.5, 3},
                             {2, 1.0, 5},
                             {3, 0.5, 8},
                             {4, 0.3, 10},
                             {5, 0.0, 20},
                             {5, -1.5, 4},
                             {0, -2.0, 6},
                             {0, 0.0, 30}},
                            kHatch);
  for (Row r : drive) {
    r.t += 30.0;
    if (r.gear == 0) r.freq = kWarmerIdle;
    rows.push_back(r);
  }
  SpeedSynthesizer synth(model);
  const auto out = replay(synth, rows, 70.0);
  REQUIRE(synth.idle_freq() > kColdIdle - 1.0);  // all GPS showed was the cold idle
  for (std::size_t i = rows.size() - 25; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t << ", synthesized " << out[i].speed << " m/s in gear " << out[i].gear);
    CHECK(out[i].speed == 0.0);
    CHECK(out[i].gear == 0);
  }
}

TEST_CASE("synth: after a long coast in an outage, steady revs go to the gear this driver runs them in") {
  // GPS is lost as the car leaves 5th and coasts out of gear for 25 s, long enough that its speed is only
  // roughly known; then it runs in 4th at steady revs. A gear entered at the wrong speed explains steady
  // revs as well as the right one, but this driver (the fit's extra.revs) runs 3rd at about 22 Hz and 4th
  // at about 30: steady revs of 30 Hz are 4th.
  auto model = std::make_shared<GearModel>(*model_of(kHatch));
  model->extra["revs"] = nlohmann::json::array();
  for (const double freq : {25.0, 24.0, 22.0, 30.0, 33.0})
    model->extra["revs"].push_back({{"mean_log", std::log(freq)}, {"sd_log", 0.15}, {"samples", 1000}});
  const auto rows = script(0.0,
                           {{0, 0.0, 10},
                            {1, 1.5, 3},
                            {2, 1.0, 5},
                            {3, 0.5, 8},
                            {4, 0.3, 10},
                            {5, 0.15, 10},
                            {5, 0.0, 20},
                            {0, -0.15, 25},
                            {4, 0.0, 60}},
                           kHatch);
  SpeedSynthesizer synth(model);
  const auto out = replay(synth, rows, 66.0);
  for (std::size_t i = rows.size() - 30; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t << ", truth " << rows[i].speed << " m/s, synthesized " << out[i].speed
                << " in gear " << out[i].gear);
    CHECK(out[i].gear == 4);
    CHECK(std::abs(out[i].speed - rows[i].speed) < 1.0);
  }
}

TEST_CASE("synth: at 10 Hz a move-off and two upshifts in an outage are followed gear by gear") {
  // Recorded from the simulator: GPS is lost as the car moves off; it shifts to second at 15 km/h and to
  // third at 25 km/h, the revs falling freely each time before the next gear bites. First gear at the
  // revs second gear shows is a car 7 km/h slower: entering a gear pays that mismatch whole, however
  // fine the steps, or the filter drifts into first gear and stays there (13 km/h at a true 36).
  int checked = 0;
  replay_recording("moveoff_upshifts", "10hz", [&](double t, double truth, const SynthOutput& out) {
    if (t < 15.0) return;  // from 15 s the car is in third gear
    INFO("t = " << t << " s: truth " << truth * 3.6 << " km/h, synthesized " << out.speed * 3.6 << " in gear "
                << out.gear);
    CHECK(out.gear == 3);
    CHECK(std::abs(out.speed - truth) < 3.0 * kKmh);
    ++checked;
  });
  CHECK(checked == 101);  // 15.0 to 25.0 s
}

TEST_CASE("synth: at 10 Hz a seven-speed climbs its ladder in an outage without falling a gear behind") {
  // Recorded from the simulator (a random 7-speed whose steps are 1.35 to 1.19): GPS is lost with the car
  // at rest; it moves off and shifts up every two to four seconds to 77 km/h (1-2-3-4-6-7). A second after
  // each shift the clutch still held a tenth of the belief with a speed that had coasted unseen, a few
  // km/h behind the car; mixed into the clutch's speed at the next declutch, that lag made the gear below
  // fit the revs when the clutch came back in, and the filter climbed the ladder one gear low (34 km/h in
  // fourth at a true 77 in seventh). Within 5 km/h: declutched for a shift, the output coasts a little
  // below the simulated car, which keeps some of its pull.
  // From 18 s, past the first shift, to the end (70 s).
  CHECK(speed_within("moveoff_seven_speed", 18.0, 70.0, 5.0 * kKmh) == 521);
}

TEST_CASE("synth: at 10 Hz a launch faster than the move-off's guess is taken up when the clutch bites") {
  // Recorded from the simulator (a random 5-speed): in a jam, GPS is lost with the car at rest; it moves
  // off hard, 0 to 20 km/h in under two seconds with the clutch slipping, then shifts up to fifth. The
  // move-off's guessed speed (a launch acceleration from rest) was 9 km/h when first gear bit at 20, and
  // entering first gear from it cost more than staying declutched; the filter then took second gear's
  // revs for first and climbed the ladder one gear low (44 km/h in fourth at a true 57 in fifth).
  // From 17 s, the clutch has bitten, to 68 s, where the car brakes hard.
  CHECK(speed_within("hard_launch_five_speed", 17.0, 68.0, 5.0 * kKmh) == 511);
}

TEST_CASE("synth: at 10 Hz a pull-away from a creep is taken up in first gear, not in a gear far above") {
  // Recorded from the simulator (a random 5-speed): in a jam, GPS is lost while the car creeps in first
  // gear at 5-9 km/h, the clutch slipping from 43 s; at 53 s the driver pulls away, the revs rising to
  // 75 Hz before the clutch bites at 12 km/h. The filter took the rise for the clutch going out on a car
  // rolling at 7 km/h; when the clutch bit, a gear entered from that roll within one step was treated as
  // a move-off biting, with the gap up to the gear's reading as its speed's spread, so fifth gear's
  // reading (42 km/h) cost nothing and the output jumped from 7 to 42 km/h in a tenth of a second, then
  // stayed a gear or more above first (40 km/h at a true 15).
  // From 56 s, the clutch has bitten, to 77 s, before the car brakes.
  CHECK(speed_within("pull_away_from_creep", 56.0, 77.0, 3.0 * kKmh) == 211);
}

TEST_CASE("synth: at 10 Hz braking with two downshifts in an outage is followed down the ladder") {
  // Recorded from the simulator (a random 4-speed): GPS is lost while the car cruises at 53 km/h; it
  // brakes to 25 km/h, shifting down twice with the revs blipped while declutched. Read as braking in the
  // old gear at one jump's cost (the acceleration reopened by a fall of revs as by a rise), the downshifts'
  // revs left a gear history that outlived them, and the filter ended two gears low (14 km/h in first at
  // a true 25 in second).
  // From 24 s, as the car brakes, to the end (70 s).
  CHECK(speed_within("braking_downshifts", 24.0, 70.0, 5.0 * kKmh) == 461);
}

TEST_CASE(
    "synth: at 10 Hz a skip downshift under braking as GPS is lost is followed in the gear it skips to") {
  // The clutch out between braking in 4th and 2nd: read with the braking carried on unchanged through the
  // declutch, the car fell at the braking rate until first gear explained 2nd gear's revs (-43 %).
  SpeedSynthesizer synth(model_of(kHatch));
  const double error = skip_downshift_outage(synth, kHatch, kIdle, true);
  INFO("outage distance error " << error << " %");
  CHECK(std::abs(error) < 2.0);
}

TEST_CASE("synth: at 10 Hz a hard move-off in an outage keeps its speed through four upshifts") {
  // Recorded from the simulator: in a jam, GPS is lost with the car at rest; it moves off hard (the revs
  // held at 27 Hz while the clutch slips, then 1.9 m/s^2 in first gear) and shifts up to fourth. While the
  // clutch slipped, first gear's history learned a steady speed; once it bites, every 0.1 s reading runs
  // ahead of that history. Paid again at each reading, that ramp lost first gear to "moving off", whose
  // ceiling then pulled the speed to 8 km/h in the shift to second, and the filter stayed one gear low
  // (15 km/h at a true 29, 24 at 82).
  // From 35 s the car is in second gear, then third and fourth, to the end (60 s).
  CHECK(speed_within("hard_launch_jam", 35.0, 60.0, 3.0 * kKmh) == 251);
}

TEST_CASE("synth: at 10 Hz a launch revved out in first gear is not lost to the clutch") {
  // Recorded from the simulator (a random 7-speed whose engine frequency is a firing frequency): in a jam,
  // GPS is lost with the car at rest; at 42 s it moves off hard and holds first gear to 191 Hz, far past
  // this driver's upshift revs, then shifts to second, third and fourth. The hazard of the upshift at such
  // revs (with first gear's time on top) grew past the cost of free revs, so the clutch took the belief
  // while the revs still followed first gear's line; the car pulled on, the clutch's speed did not, and
  // the filter took fourth gear's revs for first (11 km/h at a true 27, to the end).
  // From 42 s, as the car moves off, through first, second and third gear (51 s). The shift to fourth that
  // follows is read as a skip to fifth (docs/algorithms/synthesis-ablation.md: the entry rule).
  CHECK(speed_within("jam_revved_first", 42.0, 51.0, 3.0 * kKmh) == 90);
}

TEST_CASE("synth: at 10 Hz a driver who shifts every second or so is followed up the ladder") {
  // Recorded from the simulator (a random 6-speed): in town, GPS is lost at a light; at 29 s the car moves
  // off and shifts up every 1-2 s to fifth at 40 km/h. The clutch explains any revs, and a gear entered
  // after a shift outweighed it only a second later, just before the next shift; the clutch's speed,
  // left behind while the car pulled, was then mixed in at that declutch, and the gear below fitted the
  // revs (15 km/h in second at a true 40 in fifth). Revs that climb fast at the tracker's short steps now
  // count against the clutch. Within 4 km/h: a declutched car keeps some of its pull in the simulator.
  // From 30 s, as the car moves off, to the end (50 s).
  CHECK(speed_within("fast_shifter", 30.0, 50.0, 4.0 * kKmh) == 200);
}

TEST_CASE(
    "synth: at 1 Hz a hard climb in second is not taken for an upshift, and the upshifts are followed") {
  // Recorded from the simulator (wide-4, urban): GPS is lost at a light; the car moves off and climbs
  // hard in second (revs 22 -> 32 Hz in 2 s, no shift), then shifts to third and to fourth. Revs rising
  // that fast fit third at a higher speed too; but this driver (the fit's revs per gear) runs third at
  // about 26 Hz (+-16 %), and a shift out of second at 27 Hz would have landed at 17: the climb stays in
  // second, and the real upshifts, which land nearer his usual revs, are taken when they come.
  constexpr double kEnd = std::numeric_limits<double>::infinity();
  CHECK(speed_within("climb_in_second", 136.0, kEnd, 4.0 * kKmh, "1hz") == 44);
}

TEST_CASE(
    "synth: at 1 Hz a reading caught inside a skip-shift's declutch is the clutch's, not a jump in gear") {
  // Recorded from the simulator (hatch-5, highway, 1 Hz): GPS is lost while the car pulls in third; at 54
  // km/h, with the revs at 43 Hz, the driver shifts from third to fifth, and the reading after falls inside
  // the declutch (30 Hz, the revs falling freely). Fifth gear reads it as 62 km/h and fourth the next one
  // as 41; the declutch a shift at these revs passes through explains it at the car's own speed, and fifth
  // gear is then found at the next reading.
  constexpr double kEnd = std::numeric_limits<double>::infinity();
  CHECK(speed_within("skip_shift", 120.0, kEnd, 3.0 * kKmh, "1hz") == 61);
}

TEST_CASE("synth: at 1 Hz revs falling inside a launch's first upshift are the clutch's, not a shift done") {
  // Recorded from the simulator (bmw-520i, mixed, 1 Hz): GPS is lost as the car moves off; it pulls in
  // first gear to 144 Hz at 22 km/h, and the next reading falls inside the declutch of the shift to second
  // (117 Hz, the revs falling from first gear's line toward second's). Scored as free revs, that reading cost
  // the clutch as much as revs no mode explains: second gear took it at 30 km/h, third the next one at 36,
  // and the filter stayed a gear high, 12-13 km/h fast, to the end. Revs on their way down from the gear's
  // line are what a declutch caught mid-shift reads: the clutch holds the speed, second gear bites next.
  constexpr double kEnd = std::numeric_limits<double>::infinity();
  CHECK(speed_within("launch_declutch", 121.0, kEnd, 3.0 * kKmh, "1hz") == 59);
}

TEST_CASE("synth: at 1 Hz a launch's pull in first gear is not carried whole into second") {
  // Recorded from the simulator (compact-4, mixed, 1 Hz): GPS is lost as the car slows to a stop; it moves
  // off at 134 s and pulls hard in first gear (12 to 17 km/h in a second), then the next reading falls in
  // the declutch of the shift to second (43 Hz at 21 km/h, the revs on their way down). With first gear's
  // acceleration carried whole into second, second gear's reading of those revs (33 km/h) was a jump the
  // acceleration partly explained: second took it, third the next reading, fourth the one after the next
  // shift, and the filter stayed a gear high, 13-18 km/h fast, to the end. Through a higher gear the same
  // engine pulls the car less: second gear bites at the right speed two readings later.
  constexpr double kEnd = std::numeric_limits<double>::infinity();
  CHECK(speed_within("launch_pull", 139.0, kEnd, 3.0 * kKmh, "1hz") == 41);
}

TEST_CASE("synth: at 1 Hz a move-off read in second gear does not gain speed at first gear's pace") {
  // Recorded from the simulator (bmw-520i, traffic jam, 1 Hz): GPS is lost in a queue; the car moves off
  // at 139 s and creeps at 15 km/h in first gear near 98 Hz. Read in second gear with the launch's
  // acceleration (first gear's), the move-off gained enough speed to fit second gear's reading of the revs
  // and kept a history of its own at 25 km/h; as first gear's time grew, second took the belief at 148 s
  // and held it, 10 km/h fast, until the queue stopped again. Moving off in second gear the same engine
  // pulls the car theta_1 / theta_2 as hard: that history is not kept.
  CHECK(speed_within("creep_after_launch", 140.0, 166.0, 3.0 * kKmh, "1hz") == 27);
}

TEST_CASE("synth: from OBD polls a cruise at the low end of a gear's revs is not read a gear or two down") {
  // Recorded from the simulator (hatch-5, mixed, an OBD logger's polls: integer km/h and rpm, 1.8 s
  // rounds, skewed; the rows the reader steps): GPS is lost as the car slows from 52 to 39 km/h in fourth
  // (the fit's third: it found four of the five gears) and cruises on at 23-24 Hz, at the low end of where
  // this driver runs that gear (26 Hz, sd 0.19 in ln(freq)). With no shift down seen yet, the downshift
  // hazard followed the revs of the drive at large, and the filter slid to the gear two below, 17-22 km/h
  // slow, to the end. Against the gear's own revs, it holds.
  constexpr double kEnd = std::numeric_limits<double>::infinity();
  CHECK(speed_within("obd_cruise_fourth", 141.0, kEnd, 3.0 * kKmh, "obd") == 22);
}

TEST_CASE("synth: a split belief's contenders pull the speed as the square of their belief") {
  using gearpulse::contended_speed;
  // Between two modes, the speed of least expected |error|^1.5, found here by a search over a fine grid.
  const auto least = [](double p1, double v1, double p2, double v2) {
    double best = v2, best_cost = std::numeric_limits<double>::infinity();
    for (double a = v2; a <= v1; a += 1e-4) {
      const double cost = p1 * std::pow(v1 - a, 1.5) + p2 * std::pow(a - v2, 1.5);
      if (cost < best_cost) best = a, best_cost = cost;
    }
    return best;
  };
  for (const double p1 : {0.5, 0.6, 0.8, 0.95}) {
    const std::vector<double> prob = {p1, 1.0 - p1}, speed = {11.0, 8.5};  // third and second at 40, 31 km/h
    INFO("leader's share " << p1);
    CHECK(contended_speed(prob, speed) == Approx(least(p1, 11.0, 1.0 - p1, 8.5)).margin(1e-3));
  }
  // A clear leader keeps its speed; an even split lies halfway; one mode is its own speed; no belief, 0.
  CHECK(contended_speed(std::vector<double>{0.95, 0.05}, std::vector<double>{11.0, 8.5}) > 10.99);
  CHECK(contended_speed(std::vector<double>{0.5, 0.5}, std::vector<double>{11.0, 8.5}) == Approx(9.75));
  CHECK(contended_speed(std::vector<double>{0.0, 1.0, 0.0}, std::vector<double>{3.0, 7.0, 9.0}) == 7.0);
  CHECK(contended_speed(std::vector<double>{0.0, 0.0}, std::vector<double>{3.0, 7.0}) == 0.0);
}

TEST_CASE("synth: the output's mode is the belief's quantile by speed") {
  using gearpulse::belief_quantile_mode;
  // The q-quantile of a belief is the speed of least expected pinball loss (a slower output costs q per
  // m/s, a faster one 1 - q): found here by trying every mode's speed, over beliefs drawn at random.
  const auto least_pinball = [](const std::vector<double>& prob, const std::vector<double>& speed, double q) {
    double best = speed[0], best_cost = std::numeric_limits<double>::infinity();
    for (const double a : speed) {
      double cost = 0.0;
      for (std::size_t j = 0; j < prob.size(); ++j)
        cost += prob[j] * (speed[j] > a ? q * (speed[j] - a) : (1.0 - q) * (a - speed[j]));
      if (cost < best_cost - 1e-12) best = a, best_cost = cost;
    }
    return best;
  };
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int round = 0; round < 200; ++round) {
    const std::size_t n = 2 + round % 6;
    std::vector<double> prob(n), speed(n);
    double total = 0.0;
    for (std::size_t j = 0; j < n; ++j) {
      prob[j] = std::pow(unit(rng), 3.0);
      speed[j] = 30.0 * unit(rng);
      total += prob[j];
    }
    for (double& p : prob)
      p /= total;
    for (const double q : {0.5, 0.6, 0.65}) {
      INFO("round " << round << ", q " << q);
      const int mode = belief_quantile_mode(prob, speed, q);
      REQUIRE(mode >= 0);
      CHECK(speed[static_cast<std::size_t>(mode)] == least_pinball(prob, speed, q));
    }
  }
  // Third gear leads second 0.55 to 0.45: the median keeps third, a quantile of 0.6 takes fourth when it
  // holds the rest; a leader holding at least q is its own quantile whatever the speeds.
  const std::vector<double> speed = {8.5, 11.0, 14.0};  // second, third, fourth at 31, 40, 50 km/h
  CHECK(belief_quantile_mode(std::vector<double>{0.45, 0.55, 0.0}, speed, 0.5) == 1);
  CHECK(belief_quantile_mode(std::vector<double>{0.0, 0.55, 0.45}, speed, 0.5) == 1);
  CHECK(belief_quantile_mode(std::vector<double>{0.0, 0.55, 0.45}, speed, 0.6) == 2);
  CHECK(belief_quantile_mode(std::vector<double>{0.35, 0.65, 0.0}, speed, 0.6) == 1);
  // Modes of one speed (negligible ones carry the leader's history) count as one, named by its leader.
  CHECK(belief_quantile_mode(std::vector<double>{0.3, 0.31, 0.33, 0.06},
                             std::vector<double>{8.5, 11.0, 11.0, 14.0}, 0.6) == 2);
  CHECK(belief_quantile_mode(std::vector<double>{}, std::vector<double>{}, 0.6) == -1);
}

TEST_CASE("synth: a cold start without GPS reports no speed until it knows, then a car at rest") {
  // The daemon starts in an underground car park: no fix and, for the first moments, no frequency track.
  auto model = std::make_shared<GearModel>(*model_of(kHatch));
  model->extra["idle"] = {{"freq", kIdle}, {"sd", 0.3}, {"samples", 500}};
  SpeedSynthesizer synth(model);
  for (int k = 0; k < 5; ++k) {
    const SynthOutput out = synth.step(0.1 * k, kMissing, kMissing);
    CHECK(out.source == SpeedSource::kNone);
    CHECK(out.speed == 0.0);
    CHECK(out.gear == 0);
  }
  // Then the engine idles: a car at rest, not the most used gear at idle revs.
  for (int k = 5; k < 50; ++k) {
    const SynthOutput out = synth.step(0.1 * k, kMissing, kIdle);
    INFO("t = " << 0.1 * k);
    CHECK(out.speed == 0.0);
    CHECK(out.gear == 0);
  }
}

TEST_CASE("synth: coasting never gains speed, whatever GPS taught while no gear explained the revs") {
  // GPS ramps up at 1 m/s^2 while the engine frequency stays put (a slipping clutch, or a tracker stuck
  // on a fixed tone): no gear explains it, the filter reads declutched and GPS shows it gaining speed.
  SpeedSynthesizer synth(model_of(kHatch));
  double top = 0.0;
  for (int k = 0; k < 20; ++k)
    synth.step(k, 5.0 + k, 50.0);
  const double last_gps = 24.0;
  for (int k = 20; k < 90; ++k) {
    const SynthOutput out = synth.step(k, kMissing, 50.0);
    top = std::max(top, out.speed);
  }
  INFO("highest outage speed " << top << " m/s after GPS's last " << last_gps);
  CHECK(top <= last_gps + 3.0);
}

TEST_CASE("synth: with the frequency lost from the start the speed coasts down, it never takes off") {
  // The tracker never locks (no ripple, a card unplugged): GPS alone from a cold start at rest, then
  // GPS goes too. Moving off is how a car leaves standstill, not a state it drives in: with nothing to
  // tell the engine's revs, its launch acceleration must not carry the speed away.
  const double rate = GENERATE(1.0, 10.0);
  INFO("steps per second " << rate);
  SpeedSynthesizer synth(model_of(kHatch));
  const double gps = 16.0;
  for (int k = 0; k < static_cast<int>(10 * rate); ++k)
    synth.step(k / rate, k < static_cast<int>(2 * rate) ? kMissing : gps, kMissing);
  double top = 0.0;
  for (int k = static_cast<int>(10 * rate); k < static_cast<int>(40 * rate); ++k) {
    const SynthOutput out = synth.step(k / rate, kMissing, kMissing);
    top = std::max(top, out.speed);
    CHECK(out.source == gearpulse::SpeedSource::kCoast);
  }
  INFO("highest outage speed " << top << " m/s after GPS's " << gps);
  CHECK(top <= gps + 0.5);
}

TEST_CASE("synth: moving off inside an outage follows first gear") {
  SpeedSynthesizer synth(model_of(kHatch));
  // Stand at the light (GPS learns the idle), lose GPS, then move off: revs rise with the clutch slipping,
  // first gear bites, second follows.
  const auto rows = script(0.0, {{0, 0.0, 20}, {0, 0.0, 5}, {1, 1.5, 4}, {2, 1.0, 8}}, kHatch);
  const auto out = replay(synth, rows, 20.0);
  for (std::size_t i = 20; i < 25; ++i)
    CHECK(out[i].speed == 0.0);
  int first = 0;
  for (std::size_t i = 25; i < 29; ++i)
    first += out[i].gear == 1;
  CHECK(first >= 2);
  for (std::size_t i = 29; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].speed == Approx(rows[i].speed).margin(3.0 * kKmh));
  }
  CHECK(out.back().gear == 2);
}

TEST_CASE(
    "synth: a first gear held on after moving off gives way to second, whose upshift no reading showed") {
  // An OBD logger polls every 2 s. GPS shows the car standing, then is lost; the car moves off, and between
  // two readings the driver shifts to second and pulls the revs back up: 36 Hz in first, 33 in second. Both
  // gears explain every later reading as well (first gear at half the speed, barely accelerating), but a
  // driver does not stay in first gear at 33-46 Hz for half a minute after moving off.
  SpeedSynthesizer synth(model_of(kHatch));
  std::vector<Row> rows = standing_polled_every_2s(11);
  rows.push_back({22.0, 1.5, 22.0, 0});  // the clutch slips
  rows.push_back({24.0, 4.5, 4.5 / kHatch[0], 1});
  for (int k = 0; k < 20; ++k) {
    const double v = 7.5 + 0.2 * k;
    rows.push_back({26.0 + 2.0 * k, v, v / kHatch[1], 2});
  }
  const auto out = replay(synth, rows, 21.0);
  CHECK(out[12].gear == 1);  // first gear while it lasts
  for (std::size_t i = rows.size() - 5; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t << ", truth " << rows[i].speed * 3.6 << " km/h, synthesized "
                << out[i].speed * 3.6 << " in gear " << out[i].gear);
    CHECK(out[i].gear == 2);
    CHECK(out[i].speed == Approx(rows[i].speed).margin(1.5 * kKmh));
  }
}

TEST_CASE("synth: creeping in first gear near idle stays in first gear however long it lasts") {
  // A queue: GPS shows the car standing, then is lost while it creeps in first gear for a minute at
  // 15-19 Hz (7-9 km/h). First gear's urge to shift up grows with time only once the revs leave idle.
  for (const double dt : {0.1, 1.0, 2.0}) {
    SpeedSynthesizer synth(model_of(kHatch));
    double t = 0.0;
    for (; t < 20.0; t += dt)
      synth.step(t, 0.0, kIdle + 0.5 * std::sin(t));
    const double t0 = t;
    for (; t < t0 + 60.0; t += dt) {
      const double freq = 17.0 + 2.0 * std::sin(0.3 * (t - t0));
      const SynthOutput out = synth.step(t, kMissing, freq);
      if (t < t0 + 5.0) continue;  // first gear bites
      INFO("step " << dt << " s, t = " << t << ": synthesized " << out.speed * 3.6 << " km/h in gear "
                   << out.gear);
      CHECK(out.gear == 1);
      CHECK(out.speed == Approx(kHatch[0] * freq).margin(1.0 * kKmh));
    }
  }
}

TEST_CASE("synth: a quick move-off straight into second gear is seen under GPS and carried into the outage") {
  // An OBD logger polls every 2 s: GPS shows the car standing, slipping the clutch at 4 km/h, then already
  // at 13 km/h in second gear; GPS is lost as the car keeps accelerating in second.
  SpeedSynthesizer synth(model_of(kHatch));
  const double theta2 = kHatch[1];
  std::vector<Row> rows = standing_polled_every_2s(10);
  rows.push_back({20.0, 4.0 * kKmh, 20.6, 0});
  for (double v_kmh : {13.0, 20.0, 25.0, 29.0, 32.0})
    rows.push_back({rows.back().t + 2.0, v_kmh * kKmh, v_kmh * kKmh / theta2, 2});
  const auto out = replay(synth, rows, 23.0);
  CHECK(out[11].source == SpeedSource::kGps);
  CHECK(out[11].gear == 2);
  for (std::size_t i = 12; i < rows.size(); ++i) {
    INFO("t = " << rows[i].t);
    CHECK(out[i].source == SpeedSource::kEngine);
    CHECK(out[i].gear == 2);
    CHECK(out[i].speed == Approx(rows[i].speed).margin(1.0 * kKmh));
  }
}

TEST_CASE("synth: an outage in a gear the model lacks follows the ratio GPS showed in it") {
  // The model lacks fourth gear (a young model, or a fit that missed it). The car moves off, climbs to
  // fourth and cruises in it with GPS, then GPS is lost while it stays in fourth.
  const std::vector<double> lacking = {kHatch[0], kHatch[1], kHatch[2], kHatch[4]};
  std::vector<Row> rows;
  for (int k = 0; k < 20; ++k)
    rows.push_back({static_cast<double>(k), 0.0, kIdle, 0});
  const double drive_from = 20.0, outage_from = 80.0;
  for (Row r : script(0.0,
                      {{1, 1.5, 3},
                       {0, -0.2, 1},
                       {2, 1.2, 4},
                       {0, -0.2, 1},
                       {3, 1.0, 5},
                       {0, -0.2, 1},
                       {4, 0.5, 4},
                       {4, 0.0, 41},
                       {4, 0.3, 15},
                       {4, -0.3, 15}},
                      kHatch)) {
    r.t += drive_from;
    rows.push_back(r);
  }
  const auto distance = [&](const gearpulse::SynthTuning& tuning) {
    SpeedSynthesizer synth(model_of(lacking), tuning);
    const auto out = replay(synth, rows, outage_from);
    double synthesized = 0.0, driven = 0.0;
    for (std::size_t i = 1; i < rows.size(); ++i) {
      if (rows[i].t <= outage_from) continue;
      INFO("t = " << rows[i].t << ": truth " << rows[i].speed * 3.6 << " km/h, synthesized "
                  << out[i].speed * 3.6 << " in gear " << out[i].gear);
      const double dt = rows[i].t - rows[i - 1].t;
      synthesized += out[i].speed * dt;
      driven += rows[i].speed * dt;
    }
    // The outage runs on a gear the model does not number.
    CHECK(out.back().source == SpeedSource::kEngine);
    CHECK(out.back().gear == 0);
    return synthesized / driven - 1.0;
  };
  CHECK(std::abs(distance({})) < 0.01);
  // Without the gear measured under GPS, the outage takes one of the model's.
  gearpulse::SynthTuning without;
  without.seen_gear_fixes = std::numeric_limits<double>::infinity();
  SpeedSynthesizer blind(model_of(lacking), without);
  const auto out = replay(blind, rows, outage_from);
  CHECK(std::abs(out.back().speed / rows.back().speed - 1.0) > 0.1);
}

TEST_CASE("synth: a gear measured under GPS gives way to the model's own once a model has it") {
  const std::vector<double> lacking = {kHatch[0], kHatch[1], kHatch[2], kHatch[4]};
  SpeedSynthesizer synth(model_of(lacking));
  replay(synth, script(16.0, {{4, 0.0, 30}}, kHatch), 1e9);
  // The belief is in a gear, and in none of the model's.
  double in_model = 0.0;
  for (int g = 1; g <= 4; ++g)
    in_model += synth.mode_probability(g);
  CHECK(synth.mode_probability(0) < 0.1);
  CHECK(in_model < 0.1);
  CHECK(synth.last().gear == 0);
  REQUIRE(synth.set_model(model_of(kHatch)));
  for (double t = 30.0; t < 35.0; t += 1.0)
    synth.step(t, 16.0, 16.0 / kHatch[3]);
  CHECK(synth.last().gear == 4);
  CHECK(synth.mode_probability(4) > 0.9);
}

namespace {

// A drive at 1 s rows that stands at the light, then `stops` times moves off and climbs to third, the
// clutch out for a second at each upshift (revs between the gears' lines, the speed kept), and brakes to a
// stop with the clutch out and the engine at idle, at 1.5 m/s^2. `third` is the row where the last climb
// reaches third gear, `declutch` the row where its stop begins.
struct StopDrive {
  std::vector<Row> rows;
  std::size_t third = 0, declutch = 0;
};

StopDrive stop_drive(int stops) {
  StopDrive d;
  double t = 0.0, v = 0.0;
  const auto add = [&](int gear, double accel, int seconds, double freq) {
    for (int k = 0; k < seconds; ++k, t += 1.0) {
      v = std::max(0.0, v + accel);
      d.rows.push_back({t, v, gear > 0 ? v / kHatch[static_cast<std::size_t>(gear - 1)] : freq, gear});
    }
  };
  add(0, 0.0, 20, kIdle);
  for (int k = 0; k < stops; ++k) {
    add(1, 1.8, 3, 0.0);
    add(0, 0.0, 1, 0.5 * (v / kHatch[0] + v / kHatch[1]));
    add(2, 1.2, 4, 0.0);
    add(0, 0.0, 1, 0.5 * (v / kHatch[1] + v / kHatch[2]));
    d.third = d.rows.size();
    add(3, 0.3, 5, 0.0);
    d.declutch = d.rows.size();
    add(0, -1.5, 8, kIdle);
    add(0, 0.0, 10, kIdle);
  }
  return d;
}

// GPS lost as the drive's last climb reaches third gear: the distance over the last stop, synthesized
// against driven (relative error), and the s from the declutch to the output's rest (-1: never).
std::pair<double, double> last_stop(const StopDrive& d, SpeedSynthesizer synth) {
  const auto out = replay(synth, d.rows, d.rows[d.third].t);
  double synthesized = 0.0, driven = 0.0, rest = -1.0;
  for (std::size_t i = d.declutch; i < d.rows.size(); ++i) {
    synthesized += out[i].speed;
    driven += d.rows[i].speed;
    if (rest < 0.0 && out[i].speed == 0.0) rest = d.rows[i].t - d.rows[d.declutch].t;
  }
  return {synthesized / driven - 1.0, rest};
}

// The stop braked (last_stop of the synthesis braking) comes nearer the distance driven than the stop
// coasted, and comes to rest, sooner than the coasted one if that does at all.
void check_braked_over_coasted(std::pair<double, double> braked, std::pair<double, double> coasted) {
  INFO("distance over the stop: " << 100.0 * braked.first << " % off braked (at rest after " << braked.second
                                  << " s), " << 100.0 * coasted.first << " % coasted (" << coasted.second
                                  << " s)");
  CHECK(std::abs(braked.first) < 0.75 * std::abs(coasted.first));
  CHECK(braked.second > 0.0);
  CHECK((coasted.second < 0.0 || braked.second < coasted.second));
}

}  // namespace

TEST_CASE("synth: declutched at idle in an outage the car slows as GPS showed it braking to stops") {
  // Four stops: the last is braked in the outage as the others were under GPS, not coasted as the car
  // coasts through its shifts.
  const StopDrive drive = stop_drive(4);
  gearpulse::SynthTuning coasting;
  coasting.idle_braking = 0.0;
  check_braked_over_coasted(last_stop(drive, SpeedSynthesizer(model_of(kHatch))),
                            last_stop(drive, SpeedSynthesizer(model_of(kHatch), coasting)));
}

TEST_CASE("synth: the fit's idle braking brakes an outage's first stop before GPS showed one") {
  // One stop: GPS is lost before the car ever rolled declutched at idle under GPS, so only the model's
  // extra.idle_braking (what the fit saw of this driver's stops) tells that the car brakes rather than
  // coasting as through shifts.
  const StopDrive drive = stop_drive(1);
  auto fitted = std::make_shared<GearModel>(*model_of(kHatch));
  fitted->extra["idle_braking"] = {{"accel", -1.5}, {"seconds", 120.0}, {"samples", 120}};
  check_braked_over_coasted(last_stop(drive, SpeedSynthesizer(fitted)),
                            last_stop(drive, SpeedSynthesizer(model_of(kHatch))));
}

TEST_CASE("synth: a launch below a ladder that lacks first gear is not read in the ladder's lowest gear") {
  // A young model has third to fifth gear, not the launch gears: its lowest carries the car at idle at
  // 4.6 m/s, faster than any first gear does. At the tracker's hops, GPS shows the car standing at idle,
  // then is lost; the car moves off, the clutch slipping for 1.5 s, then pulls in first gear.
  const std::vector<double> young = {kHatch[2], kHatch[3], kHatch[4]};
  struct Hop {
    double t, speed, freq;
  };
  std::vector<Hop> hops;
  constexpr double kDt = 0.1, kLaunch = 20.0, kSlip = 1.5, kEnd = 24.0, kAccel = 1.5;
  for (double t = 0.0; t < kEnd; t += kDt) {
    const double v = t < kLaunch ? 0.0 : kAccel * (t - kLaunch);
    const double freq = t < kLaunch ? kIdle : t < kLaunch + kSlip ? 1.6 * kIdle : v / kHatch[0];
    hops.push_back({t, v, freq});
  }
  const auto distance_error = [&](const gearpulse::SynthTuning& tuning) {
    SpeedSynthesizer synth(model_of(young), tuning);
    double synthesized = 0.0, driven = 0.0;
    for (const Hop& h : hops) {
      const SynthOutput o = synth.step(h.t, h.t < 15.0 ? h.speed : kMissing, h.freq);
      if (h.t >= kLaunch) synthesized += o.speed * kDt, driven += h.speed * kDt;
    }
    return std::abs(synthesized - driven);
  };
  const double bounded = distance_error({});
  gearpulse::SynthTuning lowest_first;
  lowest_first.first_gear_idle_speed = std::numeric_limits<double>::infinity();
  const double unbounded = distance_error(lowest_first);
  INFO("distance error over the 4 s of the launch: " << bounded << " m with first gear judged lacking, "
                                                     << unbounded
                                                     << " m with the lowest gear taken for first");
  CHECK(bounded < 0.8 * unbounded);
}

TEST_CASE("synth: at 10 Hz a move-off below a ladder lacking the launch gears climbs the gears predicted") {
  // Two hard move-offs in a jam recorded from the simulator (above: two random 5-speeds, GPS lost at 10 s
  // with the car at rest), read with the model a young one has: without the launch gears, its lowest gear
  // carrying the car at idle at 3.8 and 3.3 m/s, faster than any first gear does. Read in the ladder's
  // lowest gear, the launch is overestimated and the revs' drops at its shifts match the ladder's steps
  // above, so the filter climbs gears high; with the gears below predicted from the ladder's steps it
  // climbs those.
  struct Young {
    const char* recording;
    int lacking;  // gears the young model lacks, from first up
  };
  for (const Young young : {Young{"hard_launch_five_speed", 2}, Young{"hard_launch_jam", 1}}) {
    auto model = recorded_model(young.recording);
    model->gears.erase(model->gears.begin(), model->gears.begin() + young.lacking);
    model->extra.erase("revs");  // per gear of the full ladder
    const auto distance_error = [&](const gearpulse::SynthTuning& tuning) {
      SpeedSynthesizer synth(model, tuning);
      double synthesized = 0.0, driven = 0.0;
      replay_rows(young.recording, "10hz", synth, [&](double t, double truth, const SynthOutput& out) {
        if (t < 10.0) return;  // GPS is lost at 10 s
        synthesized += 0.1 * out.speed;
        driven += 0.1 * truth;
      });
      return std::abs(synthesized - driven) / driven;
    };
    const double predicted = distance_error({});
    gearpulse::SynthTuning ladder_alone;
    ladder_alone.predict_lower_gears = 0.0;
    const double unpredicted = distance_error(ladder_alone);
    INFO(young.recording << ": distance error over the outage " << 100.0 * predicted
                         << " % with the gears below predicted, " << 100.0 * unpredicted
                         << " % with the ladder alone");
    CHECK(predicted < 0.02);
    CHECK(predicted < 0.5 * unpredicted);
  }
}

TEST_CASE("synth: a ladder lacking first gear takes the fit's gears below it over the ones predicted") {
  // A 7-speed with close low steps whose model has third to seventh gear: the fit met a ladder of all
  // seven but judged first and second too little driven for their pairs (extra.lower_gears). Predicted
  // from the ladder's steps, second gear carries the car at idle at 2.5 m/s, a first gear's speed, and the
  // prediction stops there. At the tracker's hops, GPS shows the car standing at idle, then is lost; the
  // car moves off, pulls through first, second and third gear to the revs this driver shifts at (2.6
  // idles), with the clutch out 0.4 s at each shift, and cruises in fourth.
  const std::vector<double> seven = {0.1434, 0.1894, 0.2444, 0.3095, 0.3851, 0.4714, 0.5682};
  auto model = std::make_shared<GearModel>(*model_of({seven.begin() + 2, seven.end()}));
  model->extra["lower_gears"] = {seven[0], seven[1]};
  struct Hop {
    double t, speed, freq;
  };
  std::vector<Hop> hops;
  constexpr double kDt = 0.1, kLost = 15.0, kLaunch = 20.0, kAccel = 1.5, kShift = 0.4, kCruise = 20.0;
  const double upshift = 2.6 * kIdle;
  double t = 0.0, v = 0.0;
  for (; t < kLaunch; t += kDt)
    hops.push_back({t, 0.0, kIdle});
  for (std::size_t gear = 0; gear < 3; ++gear) {  // first to third, each up to the shift revs
    for (; v / seven[gear] < upshift; t += kDt, v += kAccel * kDt)
      hops.push_back({t, v, std::max(1.6 * kIdle, v / seven[gear])});  // the clutch slips at first
    for (double s = 0.0; s < kShift; s += kDt, t += kDt)  // declutched, the revs fall toward the next gear
      hops.push_back({t, v, v / seven[gear] + (s / kShift) * (v / seven[gear + 1] - v / seven[gear])});
  }
  for (const double end = t + kCruise; t < end; t += kDt)
    hops.push_back({t, v, v / seven[3]});
  const auto distance_error = [&](const gearpulse::SynthTuning& tuning) {
    SpeedSynthesizer synth(model, tuning);
    double synthesized = 0.0, driven = 0.0;
    for (const Hop& h : hops) {
      const SynthOutput o = synth.step(h.t, h.t < kLost ? h.speed : kMissing, h.freq);
      if (h.t >= kLaunch) synthesized += o.speed * kDt, driven += h.speed * kDt;
    }
    return std::abs(synthesized - driven) / driven;
  };
  const double fitted = distance_error({});
  gearpulse::SynthTuning predicted_only;
  predicted_only.fitted_lower_gears = 0.0;
  const double predicted = distance_error(predicted_only);
  INFO("distance error over the launch and cruise: " << 100.0 * fitted << " % with the fit's gears below, "
                                                     << 100.0 * predicted << " % with the gears predicted");
  CHECK(fitted < 0.03);
  CHECK(fitted < 0.5 * predicted);
}
