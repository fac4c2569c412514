// The synthesis's clutch after a pulling gear (SynthTuning::pulled_engage): a declutch that follows a gear
// that was accelerating is most often an upshift, and the clutch lets in the gear above at the share of such
// declutches that this driver's shifts under GPS ended in it (SynthHabits::upshift_share).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>

#include "core/speed_synth.hpp"
#include "core/synth_habits.hpp"
#include "tests/town_drive.hpp"

using gearpulse::SpeedSynthesizer;
using gearpulse::SynthHabits;
using gearpulse::SynthTuning;

using gearpulse::test::hatch_model;
using gearpulse::test::TownDrive;

namespace {

// What the synthesis made of third gear's bite in the town drive's fifth cycle (TownDrive: second gear
// pulls at 1.5 m/s^2 for 4 s, 0.4 s declutched, third gear bites at 15.8 s into the cycle), GPS lost in
// second gear at 1.2 s after it bit: after four cycles under GPS (a fix a second, held at the tracker's
// 10 Hz hops), the hops from the bite until the output is third gear, and third gear's belief one hop
// after the bite.
struct Bite {
  int hops_to_third = 0;
  double third_belief = 0.0;
};
Bite third_gear_bite(const SynthTuning& tuning) {
  constexpr double kHop = 0.1;
  const double cycle = 4.0 * TownDrive::kCycle;
  const double lost = cycle + TownDrive::kSecondGear + 1.2;
  const double bite = cycle + 15.8;
  const TownDrive drive;
  SpeedSynthesizer synth(hatch_model(), tuning);
  Bite out{-1, 0.0};
  double fix = 0.0;
  for (int k = 0; k * kHop < bite + 3.0; ++k) {
    const double t = k * kHop;
    const bool fresh = k % 10 == 0;
    if (fresh) fix = drive.at(t).speed;
    const double gps = t < lost ? fix : std::numeric_limits<double>::quiet_NaN();
    const auto result = synth.step(t, gps, drive.at(t).freq, fresh);
    if (t < bite + 0.5 * kHop) continue;
    const int hops = static_cast<int>(std::lround((t - bite) / kHop));
    if (hops == 1) out.third_belief = synth.mode_probability(3);
    if (out.hops_to_third < 0 && result.gear == 3) out.hops_to_third = hops;
  }
  return out;
}

}  // namespace

TEST_CASE("synth: a declutch after a pulling gear lets in the gear above") {
  // Under GPS the driver's declutches after a pulling gear all end in the gear above; in the outage, second
  // gear pulls and the clutch goes out for 0.4 s. The clutch's belief came from second gear while it
  // pulled, so third gear is let in at the learned upshift share rather than at its share of use.
  SynthTuning off;
  off.pulled_engage = 0.0;
  const Bite with = third_gear_bite({});
  const Bite without = third_gear_bite(off);
  INFO("hops to third: " << with.hops_to_third << " (without the rule " << without.hops_to_third
                         << "); third gear's belief a hop after the bite: " << with.third_belief << " ("
                         << without.third_belief << ")");
  CHECK(with.hops_to_third >= 0);
  CHECK(with.hops_to_third <= 2);
  CHECK(with.third_belief > 0.2);
  CHECK(with.third_belief > without.third_belief);
  CHECK(with.hops_to_third < without.hops_to_third);
}

TEST_CASE("synth habits: the upshift share after a pulling gear is learned from the shifts under GPS") {
  SynthHabits habits;
  constexpr double kDt = 0.1, kMaxDeclutch = 2.0;
  // Laplace's estimate before any shift: one of the three outcomes.
  CHECK(habits.upshift_share() == Approx(1.0 / 3.0));
  const auto shift = [&](int from, int to, bool pulling, int declutched_hops) {
    habits.learn_pulled_shift(from, 0.95, true, pulling, true, kDt, kMaxDeclutch);
    for (int k = 0; k < declutched_hops; ++k)
      habits.learn_pulled_shift(0, 0.9, false, false, true, kDt, kMaxDeclutch);
    habits.learn_pulled_shift(to, 0.95, true, false, true, kDt, kMaxDeclutch);
  };
  for (int k = 0; k < 8; ++k)
    shift(2, 3, true, 4);
  CHECK(habits.upshift_share() > 0.75);
  // Shifts out of a gear that did not pull, and declutches too long to be a shift, do not count.
  const double share = habits.upshift_share();
  shift(3, 2, false, 4);
  shift(3, 3, true, 40);
  CHECK(habits.upshift_share() == Approx(share));
  // Nor does a shift not seen whole: GPS lost after the pulling gear and back in another gear.
  habits.learn_pulled_shift(2, 0.95, true, true, true, kDt, kMaxDeclutch);
  habits.forget_pulled_shift();
  habits.learn_pulled_shift(4, 0.95, true, false, true, kDt, kMaxDeclutch);
  CHECK(habits.upshift_share() == Approx(share));
  // A pulling gear taken again after a short declutch counts as the same gear; the memory is bounded, so
  // a driver who does so from now on is followed.
  for (int k = 0; k < 100; ++k)
    shift(3, 3, true, 3);
  CHECK(habits.upshift_share() < 0.2);
}
