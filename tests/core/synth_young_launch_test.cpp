// Launches on a young ladder: the launch gears it lacks, predicted from its steps, the fit's, or seen.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "core/speed_synth.hpp"
#include "tests/core/synth_drives.hpp"

using gearpulse::GearModel;
using gearpulse::kMissing;
using gearpulse::SpeedSynthesizer;
using gearpulse::SynthOutput;

using gearpulse::test::kHatch;
using gearpulse::test::kIdle;
using gearpulse::test::model_of;
using gearpulse::test::recorded_model;
using gearpulse::test::replay_rows;

namespace {

// A tracker hop: its time, the car's true speed and the engine line's frequency.
struct LaunchHop {
  double t, speed, freq;
};

// A receiver of one fix a second, as most are: the daemon gives the newest fix at every tracker hop, new at
// the first hop after it (NaN speed: no GPS).
struct OneFixASecond {
  double fix = kMissing;
  long second = -1;
  SynthOutput step(SpeedSynthesizer& synth, double t, double speed, double freq) {
    if (!std::isfinite(speed)) return synth.step(t, kMissing, freq);
    const long now = std::lround(std::floor(t + 1e-6));
    const bool fresh = now != second;
    if (fresh) fix = speed, second = now;
    return synth.step(t, fix, freq, fresh);
  }
};

constexpr double kLaunchDt = 0.1, kLaunchLost = 15.0, kLaunchAt = 20.0, kLaunchShift = 0.4;

// GPS shows the car standing at `idle` and is lost at kLaunchLost; at kLaunchAt the car moves off at
// `accel` and pulls through gears 0 to `cruise_gear` of `ratios` to `upshift` revs, with the clutch out
// kLaunchShift at each shift, then cruises `cruise` seconds in `cruise_gear`.
std::vector<LaunchHop> launch_hops(const std::vector<double>& ratios, std::size_t cruise_gear, double idle,
                                   double accel, double upshift, double cruise) {
  std::vector<LaunchHop> hops;
  double t = 0.0, v = 0.0;
  for (; t < kLaunchAt; t += kLaunchDt)
    hops.push_back({t, 0.0, idle});
  for (std::size_t gear = 0; gear < cruise_gear; ++gear) {
    for (; v / ratios[gear] < upshift; t += kLaunchDt, v += accel * kLaunchDt)
      hops.push_back({t, v, std::max(1.6 * idle, v / ratios[gear])});       // the clutch slips at first
    for (double s = 0.0; s < kLaunchShift; s += kLaunchDt, t += kLaunchDt)  // declutched, the revs fall
      hops.push_back(
          {t, v, v / ratios[gear] + (s / kLaunchShift) * (v / ratios[gear + 1] - v / ratios[gear])});
  }
  for (const double end = t + cruise; t < end; t += kLaunchDt)
    hops.push_back({t, v, v / ratios[cruise_gear]});
  return hops;
}

// The model fitted on a recording from the simulator (recorded_model), as a young model has it: without its
// `lacking` lowest gears, and without the revs per gear (recorded for the full ladder).
std::shared_ptr<GearModel> young_recorded_model(const char* recording, int lacking) {
  auto model = recorded_model(recording);
  model->gears.erase(model->gears.begin(), model->gears.begin() + lacking);
  model->extra.erase("revs");
  return model;
}

// The synthesis's distance error over a recording's outage (its 10 Hz rows, GPS lost at 10 s), a share of
// the distance driven.
double recorded_outage_error(const char* recording, std::shared_ptr<const GearModel> model,
                             const gearpulse::SynthTuning& tuning) {
  SpeedSynthesizer synth(std::move(model), tuning);
  double synthesized = 0.0, driven = 0.0;
  replay_rows(recording, "10hz", synth, [&](double t, double truth, const SynthOutput& out) {
    if (t < 10.0) return;
    synthesized += 0.1 * out.speed;
    driven += 0.1 * truth;
  });
  return std::abs(synthesized - driven) / driven;
}

// The synthesis's distance error over the launch and cruise of `hops`, a share of the distance driven.
double launch_distance_error(std::shared_ptr<const GearModel> model, const gearpulse::SynthTuning& tuning,
                             const std::vector<LaunchHop>& hops) {
  SpeedSynthesizer synth(std::move(model), tuning);
  double synthesized = 0.0, driven = 0.0;
  for (const LaunchHop& h : hops) {
    const SynthOutput o = synth.step(h.t, h.t < kLaunchLost ? h.speed : kMissing, h.freq);
    if (h.t >= kLaunchAt) synthesized += o.speed * kLaunchDt, driven += h.speed * kLaunchDt;
  }
  return std::abs(synthesized - driven) / driven;
}

}  // namespace

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
    const auto model = young_recorded_model(young.recording, young.lacking);
    const auto distance_error = [&](const gearpulse::SynthTuning& tuning) {
      return recorded_outage_error(young.recording, model, tuning);
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
  // First to third gear, each up to the shift revs, then fourth.
  const auto hops = launch_hops(seven, 3, kIdle, 1.5, 2.6 * kIdle, 20.0);
  const auto distance_error = [&](const gearpulse::SynthTuning& tuning) {
    return launch_distance_error(model, tuning, hops);
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

TEST_CASE("synth: a launch through gears missing inside a young ladder climbs the gears predicted there") {
  // A 7-speed whose young model has second, fifth, sixth and seventh gear: first, third and fourth were
  // passed in launches, never driven steadily. The step from its second to its fifth gear (a factor of
  // 2.3) is three gearbox steps. At the tracker's hops, GPS shows the car standing at idle, then is lost;
  // the car moves off and pulls through every gear to the revs this driver shifts at (5 idles), with the
  // clutch out 0.4 s at each shift, and cruises in seventh. The launch in first gear is read in second
  // (the model's lowest carries the car at idle at a first gear's speed, so none is predicted below it).
  const std::vector<double> seven = {0.0145, 0.0200, 0.0270, 0.0358, 0.0463, 0.0590, 0.0737};
  constexpr double kCarIdle = 47.0;  // Hz: first gear carries the car at 0.7 m/s at idle
  const auto model = model_of({seven[1], seven[4], seven[5], seven[6]});
  const auto hops = launch_hops(seven, 6, kCarIdle, 1.2, 5.0 * kCarIdle, 30.0);
  const auto distance_error = [&](const gearpulse::SynthTuning& tuning) {
    return launch_distance_error(model, tuning, hops);
  };
  SpeedSynthesizer filled(model);
  CHECK(filled.ladder_gears() == 6);  // two gears predicted in the step from second to fifth
  const double with_gaps = distance_error({});
  gearpulse::SynthTuning ladder_alone;
  ladder_alone.fill_ladder_gaps = 0.0;
  const double without = distance_error(ladder_alone);
  INFO("distance error over the launch and cruise: " << 100.0 * with_gaps << " % with the gears in the step "
                                                     << "predicted, " << 100.0 * without << " % without");
  CHECK(with_gaps < 0.1);
  CHECK(with_gaps < 0.5 * without);
}

TEST_CASE("synth: launches seen under GPS tell a ladder whose lowest gear could be first that it is not") {
  // The 7-speed above, whose young model has second, fifth, sixth and seventh gear: its second carries the
  // car at idle at 0.9 m/s, a first gear's speed, so the idle predicts no gear below it. Under GPS the car
  // stands at idle, moves off and pulls through every gear, the revs falling at each shift: one upshift
  // before the filter holds the model's lowest gear, first gear below it. It brakes to rest declutched,
  // GPS is lost, and it moves off again the same way: the launch is read in the gears the ladder has.
  const std::vector<double> seven = {0.0145, 0.0200, 0.0270, 0.0358, 0.0463, 0.0590, 0.0737};
  constexpr double kCarIdle = 47.0;
  struct Hop {
    double t, speed, freq;
  };
  std::vector<Hop> hops;
  constexpr double kDt = 0.1, kStand = 20.0, kAccel = 1.2, kShift = 0.4, kCruise = 15.0, kBrake = 2.0;
  const double upshift = 5.0 * kCarIdle;
  double t = 0.0, v = 0.0, braked = 0.0;
  const auto stand = [&](double seconds) {
    for (const double end = t + seconds; t < end; t += kDt)
      hops.push_back({t, 0.0, kCarIdle});
  };
  const auto launch_and_stop = [&](std::size_t first) {
    for (std::size_t gear = first; gear + 1 < seven.size(); ++gear) {
      for (; v / seven[gear] < upshift; t += kDt, v += kAccel * kDt)
        hops.push_back({t, v, std::max(1.6 * kCarIdle, v / seven[gear])});  // the clutch slips at first
      for (double s = 0.0; s < kShift; s += kDt, t += kDt)
        hops.push_back({t, v, v / seven[gear] + (s / kShift) * (v / seven[gear + 1] - v / seven[gear])});
    }
    for (const double end = t + kCruise; t < end; t += kDt)
      hops.push_back({t, v, v / seven[6]});
    braked = t;
    for (; v > 0.0; t += kDt, v = std::max(0.0, v - kBrake * kDt))  // declutched, the revs fall to idle
      hops.push_back({t, v, kCarIdle});
  };
  stand(kStand);
  launch_and_stop(0);
  stand(kStand);
  const double lost = t - 5.0, relaunch = t;
  launch_and_stop(0);
  const auto model = model_of({seven[1], seven[4], seven[5], seven[6]});
  const auto distance_error = [&](const gearpulse::SynthTuning& tuning, int& ladder) {
    SpeedSynthesizer synth(model, tuning);
    OneFixASecond gps;
    double synthesized = 0.0, driven = 0.0;
    for (const Hop& h : hops) {
      const SynthOutput o = gps.step(synth, h.t, h.t < lost ? h.speed : kMissing, h.freq);
      if (h.t >= relaunch && h.t < braked) synthesized += o.speed * kDt, driven += h.speed * kDt;
    }
    ladder = synth.ladder_gears();
    return std::abs(synthesized - driven) / driven;
  };
  int counted_ladder = 0, idle_ladder = 0;
  const double counted = distance_error({}, counted_ladder);
  gearpulse::SynthTuning idle_alone;
  idle_alone.launch_gears = 0.0;
  const double without = distance_error(idle_alone, idle_ladder);
  CHECK(idle_ladder == 6);     // two gears predicted between second and fifth
  CHECK(counted_ladder == 7);  // and first below second
  INFO("distance error over the launch and cruise in the outage: "
       << 100.0 * counted << " % with the launch seen, " << 100.0 * without << " % with the idle alone");
  CHECK(counted < 0.05);
  CHECK(counted < 0.5 * without);
}

TEST_CASE("synth: launches seen under GPS from a ladder's lowest gear add no gear below it") {
  // The same car with a model of first, second, fifth, sixth and seventh gear: the launches under GPS
  // reach first gear with no upshift, and nothing is predicted below it.
  const std::vector<double> seven = {0.0145, 0.0200, 0.0270, 0.0358, 0.0463, 0.0590, 0.0737};
  constexpr double kCarIdle = 47.0, kDt = 0.1, kAccel = 1.2, kShift = 0.4;
  SpeedSynthesizer synth(model_of({seven[0], seven[1], seven[4], seven[5], seven[6]}));
  REQUIRE(synth.ladder_gears() == 7);
  double t = 0.0;
  for (int launch = 0; launch < 3; ++launch) {
    double v = 0.0;
    for (const double end = t + 10.0; t < end; t += kDt)
      synth.step(t, 0.0, kCarIdle);
    for (std::size_t gear = 0; gear < 3; ++gear) {
      for (; v / seven[gear] < 5.0 * kCarIdle; t += kDt, v += kAccel * kDt)
        synth.step(t, v, std::max(1.6 * kCarIdle, v / seven[gear]));
      for (double s = 0.0; s < kShift; s += kDt, t += kDt)
        synth.step(t, v, v / seven[gear] + (s / kShift) * (v / seven[gear + 1] - v / seven[gear]));
    }
    for (; v > 0.0; t += kDt, v = std::max(0.0, v - 2.0 * kDt))
      synth.step(t, v, kCarIdle);
  }
  CHECK(synth.ladder_gears() == 7);
}

TEST_CASE("synth: launches seen under GPS from a motorcycle's first gear take back the gear the idle adds") {
  // A motorcycle idles at 1300 rpm (the crank line at 21.7 Hz) and its first gear carries it at 3.2 m/s
  // there, faster than a car's first gear does: once GPS shows the idle, a gear is predicted below first.
  // Its launches under GPS reach first gear with no upshift: the gear predicted goes.
  const std::vector<double> six = {0.1475, 0.1991, 0.2429, 0.2866, 0.3210, 0.3531};
  constexpr double kBikeIdle = 21.7, kDt = 0.1, kAccel = 2.5, kShift = 0.3;
  SpeedSynthesizer synth(model_of(six));
  double t = 0.0;
  int idle_ladder = 0;
  for (int launch = 0; launch < 3; ++launch) {
    double v = 0.0;
    for (const double end = t + 10.0; t < end; t += kDt)
      synth.step(t, 0.0, kBikeIdle);
    if (launch == 0) idle_ladder = synth.ladder_gears();
    for (std::size_t gear = 0; gear < 3; ++gear) {
      for (; v / six[gear] < 4.0 * kBikeIdle; t += kDt, v += kAccel * kDt)
        synth.step(t, v, std::max(1.6 * kBikeIdle, v / six[gear]));  // the clutch slips at first
      for (double s = 0.0; s < kShift; s += kDt, t += kDt)
        synth.step(t, v, v / six[gear] + (s / kShift) * (v / six[gear + 1] - v / six[gear]));
    }
    for (; v > 0.0; t += kDt, v = std::max(0.0, v - 2.0 * kDt))  // declutched, the revs at idle
      synth.step(t, v, kBikeIdle);
  }
  CHECK(idle_ladder == 7);
  CHECK(synth.ladder_gears() == 6);
}

TEST_CASE("synth: a launch from rest partly unseen counts no gears below the ladder") {
  // The young 7-speed model without first gear above: a launch under GPS shows first gear below its
  // lowest. The car then stands under GPS and moves off through first unseen (no steps for longer than
  // max_gap, or no ladder to follow the launch on), and is seen again in second gear under GPS: what the
  // launch passed unseen is not counted, and the count of gears below stays the first launch's.
  const std::vector<double> seven = {0.0145, 0.0200, 0.0270, 0.0358, 0.0463, 0.0590, 0.0737};
  constexpr double kCarIdle = 47.0, kDt = 0.1, kAccel = 1.2, kShift = 0.4;
  const auto model = model_of({seven[1], seven[4], seven[5], seven[6]});
  SpeedSynthesizer synth(model);
  OneFixASecond gps;
  REQUIRE(synth.ladder_gears() == 6);
  double t = 0.0, v = 0.0;
  const auto stand = [&](double seconds) {
    for (const double end = t + seconds; t < end; t += kDt)
      gps.step(synth, t, 0.0, kCarIdle);
  };
  const auto through = [&](std::size_t first, std::size_t last) {  // gears first..last-1, shifting up
    for (std::size_t gear = first; gear < last; ++gear) {
      for (; v / seven[gear] < 5.0 * kCarIdle; t += kDt, v += kAccel * kDt)
        gps.step(synth, t, v, std::max(1.6 * kCarIdle, v / seven[gear]));
      for (double s = 0.0; s < kShift; s += kDt, t += kDt)
        gps.step(synth, t, v, v / seven[gear] + (s / kShift) * (v / seven[gear + 1] - v / seven[gear]));
    }
  };
  const auto cruise_and_stop = [&](std::size_t gear) {
    for (const double end = t + 10.0; t < end; t += kDt)
      gps.step(synth, t, v, v / seven[gear]);
    for (; v > 0.0; t += kDt, v = std::max(0.0, v - 2.0 * kDt))
      gps.step(synth, t, v, kCarIdle);
  };
  stand(20.0);
  through(0, 3);
  cruise_and_stop(3);
  stand(20.0);
  REQUIRE(synth.ladder_gears() == 7);  // first gear predicted below second
  SECTION("no steps for longer than max_gap") {
    t += gearpulse::SynthTuning{}.max_gap + 10.0;
    v = 2.0 * kCarIdle * seven[1];
  }
  SECTION("no ladder") {
    synth.set_model(nullptr);
    through(0, 1);
    synth.set_model(model);
  }
  through(1, 3);
  cruise_and_stop(3);
  CHECK(synth.ladder_gears() == 7);
}
