// A young ladder's top: a gear held in a top step too large, and a gear predicted above its top gear.
#include <catch2/catch.hpp>

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
using gearpulse::test::replay;
using gearpulse::test::script;

namespace {

// The speed output at the end of an outage at the tracker's hops (0.1 s): 30 s cruising under GPS at `cruise`
// m/s in the gear of `theta_from`; GPS lost, braking in that gear to `braked` m/s over `brake_s`; 0.5 s
// declutched (20 Hz); then `drive_s` in the gear of `theta_to` at `speed` m/s.
double downshift_outage_speed(std::shared_ptr<const GearModel> model, const gearpulse::SynthTuning& tuning,
                              double theta_from, double cruise, double braked, double brake_s,
                              double theta_to, double speed, double drive_s) {
  SpeedSynthesizer synth(std::move(model), tuning);
  const double braked_at = 30.0 + brake_s, engaged_at = braked_at + 0.5;
  double t = 0.0;
  for (; t < 30.0; t += 0.1)
    (void)synth.step(t, cruise, cruise / theta_from);
  for (; t < braked_at; t += 0.1)
    (void)synth.step(t, kMissing, (cruise - (cruise - braked) * (t - 30.0) / brake_s) / theta_from);
  for (; t < engaged_at; t += 0.1)
    (void)synth.step(t, kMissing, 20.0);
  SynthOutput o{};
  for (; t < engaged_at + drive_s; t += 0.1)
    o = synth.step(t, kMissing, speed / theta_to);
  return o.speed;
}

}  // namespace

TEST_CASE("synth: a top step larger than the step below it by more than steps grow holds a gear") {
  // A 6-speed whose young model has second, third and fifth gear: fourth was passed in launches, never
  // driven steadily. The model's top step (0.53) is 1.7 times the step below it (0.31), where a gearbox's
  // steps shrink toward the top: it holds two, the gear predicted at its middle 1.5 % off the true fourth.
  // Under GPS the car cruises in fifth at 15 m/s; GPS is lost, the car brakes in fifth to 12 m/s, declutches
  // 0.5 s and drives on in fourth: its revs are read at that gear's speed, not at third's (24 % slow) or
  // fifth's (28 % fast).
  const std::vector<double> six = {0.0550, 0.0788, 0.1083, 0.1433, 0.1834, 0.2280};
  const auto model = model_of({six[1], six[2], six[4]});
  const auto outage_speed = [&](const gearpulse::SynthTuning& tuning) {  // braking in fifth to 12 m/s
    return downshift_outage_speed(model, tuning, six[4], 15.0, 12.0, 6.0, six[3], 12.0, 23.5);
  };
  CHECK(SpeedSynthesizer(model).ladder_gears() >= 4);
  gearpulse::SynthTuning without;
  without.fill_top_step = 0.0;
  INFO("speed in fourth at 12 m/s: " << outage_speed({}) << " m/s with the top step filled, "
                                     << outage_speed(without) << " m/s without");
  CHECK(outage_speed({}) == Approx(12.0).epsilon(0.05));
  CHECK(std::abs(outage_speed(without) - 12.0) > 2.0);
}

TEST_CASE("synth: a gear predicted inside the ladder is held as long as the gears beside it") {
  // A 5-speed whose young model lacks fourth: its top step (0.54) is 1.6 times the step below it, and the
  // gear predicted there lies 2 % off the true fourth. Under GPS the car cruises in fifth at 21 m/s; GPS is
  // lost, the car brakes in fifth to 13 m/s, declutches 0.5 s and drives on in fourth at 12 m/s for 20 s.
  // Used for the least share of use, the predicted gear is left within seconds for third, whose reading
  // (9 m/s) the speed can fall to in that time; used as the gears beside it, it is held.
  const std::vector<double> five = {0.0846, 0.1250, 0.1749, 0.2334, 0.2991};
  const auto model = model_of({five[0], five[1], five[2], five[4]});
  const auto outage_speed = [&](const gearpulse::SynthTuning& tuning) {  // braking in fifth to 13 m/s
    return downshift_outage_speed(model, tuning, five[4], 21.0, 13.0, 6.0, five[3], 12.0, 20.0);
  };
  gearpulse::SynthTuning least;
  least.gap_gear_share = 0.0;
  INFO("speed in fourth at 12 m/s: " << outage_speed({}) << " m/s used as the gears beside it, "
                                     << outage_speed(least) << " m/s for the least share");
  CHECK(outage_speed({}) == Approx(12.0).epsilon(0.05));
  CHECK(std::abs(outage_speed(least) - 12.0) > 1.5);
}

namespace {

// The hatch's young model of second to fourth gear, with the fit's idle and its revs per gear (extra.revs,
// mean_log and sd_log 0.2 in ln Hz): second and third at `low_mean_log`, fourth at `top_mean_log`.
std::shared_ptr<GearModel> young_hatch(double low_mean_log, double top_mean_log, int top_samples = 100) {
  auto m = std::make_shared<GearModel>(*model_of({kHatch[1], kHatch[2], kHatch[3]}));
  m->extra["idle"] = {{"freq", kIdle}, {"sd", 0.3}, {"samples", 100}};
  m->extra["revs"] = nlohmann::json::array();
  for (double mean_log : {low_mean_log, low_mean_log})
    m->extra["revs"].push_back({{"mean_log", mean_log}, {"sd_log", 0.2}, {"samples", 100}});
  m->extra["revs"].push_back({{"mean_log", top_mean_log}, {"sd_log", 0.2}, {"samples", top_samples}});
  return m;
}

}  // namespace

TEST_CASE("synth: an outage in a gear above a young ladder's top is read in the gear predicted there") {
  // The hatch's young model has second to fourth gear, each run in the same band of revs: the car has not
  // yet cruised in fifth. GPS shows it standing at idle, moving off through the gears and cruising in
  // fourth; then GPS is lost, and the car shifts up into fifth and drives on. Fourth gear, the ladder's
  // top, reads fifth's revs 18 % slow; the gear predicted above it from the ladder's shrinking steps
  // (0.584 (m/s)/Hz) is 2 % off the true fifth.
  const auto young = young_hatch(3.3, 3.3);
  const double drive_from = 20.0;
  const auto rows = script(0.0,
                           {{0, 0.0, drive_from},
                            {1, 1.5, 3},
                            {0, -0.2, 1},
                            {2, 1.2, 4},
                            {0, -0.2, 1},
                            {3, 1.0, 5},
                            {0, -0.2, 1},
                            {4, 0.5, 6},
                            {4, 0.0, 30},
                            {0, -0.2, 1},
                            {5, 0.3, 15},
                            {5, 0.0, 40}},
                           kHatch);
  const double outage_from = drive_from + 50.0;  // the car in fourth, ten seconds before the upshift
  const auto distance_error = [&](const gearpulse::SynthTuning& tuning) {
    SpeedSynthesizer synth(young, tuning);
    const auto out = replay(synth, rows, outage_from);
    double synthesized = 0.0, driven = 0.0;
    for (std::size_t i = 1; i < rows.size(); ++i) {
      if (rows[i].t <= outage_from) continue;
      INFO("t = " << rows[i].t << ": truth " << rows[i].speed * 3.6 << " km/h, synthesized "
                  << out[i].speed * 3.6 << " in gear " << out[i].gear);
      synthesized += out[i].speed;
      driven += rows[i].speed;
    }
    return synthesized / driven - 1.0;
  };
  const double predicted = distance_error({});
  gearpulse::SynthTuning ladder_alone;
  ladder_alone.predict_upper_gears = 0.0;
  const double without = distance_error(ladder_alone);
  INFO("distance error over the outage: " << 100.0 * predicted << " % with the gear above predicted, "
                                          << 100.0 * without << " % without");
  CHECK(std::abs(predicted) < 0.04);
  CHECK(without < -0.1);
}

TEST_CASE("synth: a gear is predicted above a top gear the fit saw run no higher than the gear below it") {
  // The fit's revs per gear say whether the young ladder's top gear was run where a driver leaves a gear
  // for the next (the band of the gear below it), or above that, as only a gear with none above is.
  // Below its lowest gear a first gear is predicted either way (its lowest carries the car at idle at
  // 3 m/s, faster than a first gear does).
  CHECK(SpeedSynthesizer(young_hatch(3.4, 3.3)).ladder_gears() == 5);
  CHECK(SpeedSynthesizer(young_hatch(3.4, 3.6)).ladder_gears() == 4);
  gearpulse::SynthTuning revs_ignored;
  revs_ignored.top_gear_revs = 0.0;
  CHECK(SpeedSynthesizer(young_hatch(3.4, 3.6), revs_ignored).ladder_gears() == 5);
  // A model that records no revs says nothing of it: no gear is predicted above.
  CHECK(SpeedSynthesizer(model_of({kHatch[1], kHatch[2], kHatch[3]})).ladder_gears() == 3);
}

TEST_CASE("synth: no gear is predicted above a top gear cruised in for long") {
  // A driver with a gear above the top one seen shifts into it within minutes of cruising: a top gear the
  // fit saw on 2,000 pairs (over half an hour at 1 Hz) is the gearbox's top, whatever its revs.
  CHECK(SpeedSynthesizer(young_hatch(3.4, 3.3, 2000)).ladder_gears() == 4);
  CHECK(SpeedSynthesizer(young_hatch(3.4, 3.3, 200)).ladder_gears() == 5);
  gearpulse::SynthTuning ungated;
  ungated.upper_gear_samples = std::numeric_limits<double>::infinity();
  CHECK(SpeedSynthesizer(young_hatch(3.4, 3.3, 2000), ungated).ladder_gears() == 5);
}
