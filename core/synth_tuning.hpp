#pragma once
// The constants of the speed synthesis (SpeedSynthesizer, core/speed_synth.hpp), each with the physical
// argument or the measurement it rests on.
#include "core/gear_model.hpp"
#include "core/speed_lag.hpp"

namespace gearpulse {

// Driving-physics constants (not from the paper): how road cars accelerate, how drivers shift and move
// off. They are deliberately generic, not fitted to any one log; what differs between cars and drivers
// (idle, shift points, how hard the car slows declutched) is learned online while GPS is present.
struct SynthTuning {
  double accel_sigma = 0.8;   // m/s^2: spread of a driver's acceleration in gear
  double accel_time = 3.0;    // s: how long an acceleration persists
  double coast_accel = -0.6;  // m/s^2: declutched and moving (rolling, braking); weighs as 10 fixes learned
  double coast_sigma = 0.8;   // m/s^2
  double coast_time = 8.0;    // s: declutched, a braking or rolling deceleration persists
  double stop_speed = 4.0;    // m/s: declutched below this, the car is being braked to a stop
  double stop_accel = -1.5;   // m/s^2: ... at an ordinary firm deceleration
  double launch_accel = 1.8;  // m/s^2: moving off while the clutch slips
  double launch_sigma = 1.0;  // m/s^2
  // In gear the brakes go on from one moment to the next (a pedal pressed within a few tenths of a second),
  // not over accel_time as the acceleration's drift has it: brake_rate (1/s) is how often a driver does so,
  // about twice a minute in town (0: never), and brake_sigma (m/s^2) the least spread of the acceleration
  // at that moment (ordinary braking reaches 1-3 m/s^2).
  double brake_rate = 0.03;
  double brake_sigma = 1.0;
  double gear_dwell = 8.0;      // s: mean time in a gear of average use before it is left
  double engage_rate = 1.0;     // 1/s: declutched -> a gear while moving (a shift takes about a second)
  double launch_rate = 0.2;     // 1/s: standing -> moving off (the frequency tells when)
  double bite_rate = 0.7;       // 1/s: moving off -> the clutch has bitten
  double launch_second = 0.1;   // share of drivers' launches made in second gear
  double skip_share = 0.1;      // share of shifts that skip a gear
  double evidence_time = 1.0;   // s: correlation time of the frequency's departures from the model
  double idle_weight = 0.6;     // share of the declutched frequency density in the idle spike
  double lugging_first = 0.2;   // relative chance of first gear with the engine lugged (creeping)
  double lugging_other = 0.05;  // same for higher gears, below the revs their driver holds them at
  // s: first gear is a launch gear, left for second within seconds of moving off: its upshift rate grows
  // with the time spent in it, by 1 + (time / launch_gear_time)^2 (at most 6x; none while the revs stay
  // near idle, creeping), where other gears' rates do not depend on how long they have been held.
  double launch_gear_time = 3.0;
  // Weight, per second in a gear, of how usual the revs are in that gear for this driver (the model's
  // per-gear revs, recorded by the fit): a wrong gear that explains steady revs as well as the right one
  // loses to it at this rate. Tuned, not a count of independent readings: the revs' own correlation time
  // within a gear is a minute or more on every fit, and weighed by it the habit does no more than without
  // it (synthesis-experiments.md, "The revs priors weighed by the revs' own correlation time"); it drains
  // a wrong gear against the leak the transitions feed it, at 2-3 times a gear's mean leave rate.
  double revs_habit = 0.3;
  // Exponent on how much nearer a shift brings the revs to the band this driver runs the new gear in
  // (model extra.revs), as a factor on the rate of that shift; tuned as revs_habit is.
  double shift_comfort = 0.3;
  double min_speed_sigma = 0.15;  // m/s: floor on the model's sigma_v (integer km/h logs, GPS noise)
  double min_freq_rel = 0.01;     // floor on sigma_s as a fraction of the frequency (tracking jitter)
  double stationary_speed = 0.3;  // m/s: GPS speed below this is "standing" (idle is learned there)
  // Hz: the lowest frequency a reading can show (the tracker's band, tracker.band_low; 0: any). An engine
  // whose warm idle the fit saw below it idles where no reading reaches: what is read with the car at rest
  // is then a slipping clutch, a blip or a harmonic, never the idle, and the standing idle stays the fit's.
  double reading_floor = 0.0;
  double max_gap = 30.0;  // s: a longer gap between steps forgets the speed track
  // Without a gear ladder (no model yet, an automatic or CVT) the frequency says nothing of the speed: an
  // outage holds the last GPS speed this long (a tunnel's speed is most likely the speed going in), then
  // comes down to rest at coast_accel (a long outage most likely ends parked).
  double hold_time = 60.0;  // s
  // Share of the contenders' speed (contended_speed) in an outage's output, the rest the speed of the mode
  // at the belief's output_quantile (below). The median mode errs least in absolute terms where the belief is
  // right about its odds; on 1-2 s readings it is overconfident (a most probable mode holding 0.5-0.8 of it
  // is the right gear 36-41 % of the time on the Etios logs), and a wrong gear held whole is the error that
  // matters.
  double hedge_share = 0.5;
  // Quantile of the belief, ordered by speed, whose mode carries an outage's output (belief_quantile_mode).
  // Above the median: a wrong gear is far more often a slower one than a faster one (with the median, 8.6 %
  // of the Etios logs' outage samples are more than 8 km/h off in a slower gear and 2.1 % in a faster one,
  // the Swift's 17-27 % against 3 %; `bench_real_logs`), since the revs favour a slower gear's vaguer
  // prediction and an upshift's readings are easily read as braking: a faster contender is outranked more
  // often than the belief says. Kept below 2/3, where a first gear creeping near idle, whose belief second
  // gear shares by a third, would be output as second.
  double output_quantile = 0.6;
  // Rules of the filter that bench_outage's --ablate switches off one at a time (each line: the rule, and
  // the value at which it is absent).
  // Rolling declutched, revs climbing faster than 0.2 a second at the tracker's hops are an engine pulling
  // the car: at 0.4 a second they cost the clutch this share of a second of free revs on top (0: none).
  double climb_cost = 1.0;
  // s: the clutch is out this long in a shift; between readings further apart than the tracker's hops, a
  // reading falls inside an upshift's declutch with this share of the step (0: never).
  double declutch_time = 0.5;
  // 1: a declutch that follows a pulling gear (its acceleration more than one of its spreads above 0) is
  // most often an upshift: the share of the clutch's belief that came from gear g while it pulled, fading
  // over declutch_time spent declutched, engages gear g + 1 at the upshift share this driver's shifts after
  // a pulling gear show under GPS (SynthHabits::upshift_share); the rest of the clutch's engagement goes to
  // every gear in proportion to its use (0: all of it does).
  double pulled_engage = 1.0;
  // At the tracker's hops through an outage the clutch keeps no speed history of its own while it holds
  // less than this share of the leading gear's belief (0: it always keeps its own).
  double clutch_track_share = 0.5;
  // 1/s: the most a gear's hazard of being left may reach, the cost of a second of free revs (infinity:
  // no cap).
  double leave_cap = 4.5;
  // 1: at the tracker's hops, a clutch biting after a move-off takes the gap up to the gear's reading as
  // its speed's spread (0: the move-off's own spread).
  double bite_gap = 1.0;
  // 1: at the tracker's hops, a gear's reading beyond the dead zone upward reopens the acceleration's
  // spread (0: it never does).
  double jump_reopen = 1.0;
  // 1: between readings further apart than the tracker's hops, before downshifts were seen, a gear's revs
  // band (extra.revs) stands in for the downshift revs (0: the revs run in gear at large do).
  double downshift_band = 1.0;
  // 1: a gear's leave rate scales with how little it is used (a first gear is left soon) (0: every gear
  // is left at 1 / gear_dwell).
  double dwell_by_use = 1.0;
  // 1: revs between the idle learned last and the fit's warm idle are idle (a warming engine) (0: only
  // the idle learned).
  double warm_floor = 1.0;
  // 1: the rolling idle learned under GPS holds declutched revs on the move (0: the standing idle does).
  double rolling_idle = 1.0;
  // 1: once a gear was seen left a few times, its own shift revs count (0: those of all gears).
  double gear_shift_points = 1.0;
  // 1: declutched on the move at idle revs, the idle is learned too (0: only standing).
  double idle_on_move = 1.0;
  // 1: a shift carries the pull's acceleration into the new gear as theta_old / theta_new (0: whole).
  double pull_transfer = 1.0;
  // 1: a GPS fix beyond the dead zone teaches the acceleration no more than the dead zone's worth (0: all).
  double gps_accel_clip = 1.0;
  // 1/s: log-cost of being in a gear while the frequency is lost for longer than 1 s, longer than the
  // tracker's gaps (0: a lost reading says nothing).
  double lost_gear_cost = 3.0;
  // 1: through an outage, a hop the tracker refuses (within a gap of 1 s or less) is no step of the filter:
  // the next reading takes the whole gap as one step, every mode's history scored against it from where it
  // stood before the gap (0: every hop of a gap is a step of its own).
  double gap_one_step = 1.0;
  // 1: moving off grows less plausible as the car gains speed (0: as plausible at any speed).
  double launch_fade = 1.0;
  // 1: declutched slower than stationary_speed, the output is 0 (0: the belief's speed, however slow).
  double rest_output = 1.0;
  // Steady fixes in a row (GPS speed and revs agreeing on one ratio at a steady speed, seen_gears.hpp) at a
  // ratio off every gear of the model before the synthesis carries that ratio as a gear the model lacks
  // (inf: never). A young model lacks the gears not yet driven, a fit may drop a rarely used gear. Two such
  // fixes after a first are a gear held for two readings' time at one speed: no shift or clutch biting
  // holds the revs at a gear's ratio that long.
  double seen_gear_fixes = 2.0;
  // 1: a gear seen under GPS only at lugged revs (SynthHabits::lugged: below those this driver holds any
  // gear above first at) may be a creep, a clutch slipping at held revs, whose ratio of speed to revs is no
  // gear's: at revs that are not lugged it is scored as a gear driven lugged is (lugging_other) (0: as
  // any gear).
  double creep_gears = 1.0;
  // 1: declutched on the move with the engine at idle (not in a shift), the car slows at the deceleration
  // GPS showed in that state, a driver's habit of braking to a stop or rolling (0: at the deceleration
  // learned declutched at large, shifts included, whatever the revs).
  double idle_braking = 1.0;
  // s of fixes at most that the fit's deceleration declutched at idle (the model's extra.idle_braking) is
  // worth before GPS shows this drive's (0: none; the drive starts from the deceleration declutched at
  // large).
  double idle_braking_prior = 3.0;
  // m/s: the most first gear carries a car at idle (kFirstGearIdleSpeed, the fit's bound). A model whose
  // lowest gear carries it faster at the warm idle lacks first gear (a young model has not seen the launch
  // gears steady): a move-off's clutch then bites in a gear below the ladder, so its speed is not given the
  // spread up to a gear's reading as it would be were that gear first (bite_gap), and moving off stands for
  // driving below the ladder, as plausible at speed as at a walking pace (launch_fade does not apply) (inf:
  // the lowest gear is always first).
  double first_gear_idle_speed = kFirstGearIdleSpeed;
  // Share of the deceleration a declutch carries that is its spread: with the clutch out the driver may
  // keep braking, ease off or stop braking (a downshift under braking), so the deceleration GPS measured
  // in gear is known no better than its own size once the clutch goes out. A gear the revs show next is
  // then entered from that spread of speeds, not from the braking carried on unchanged (0: the
  // deceleration stays as certain as GPS measured it).
  double declutch_brake_spread = 1.0;
  // 1: a pulling gear's history that goes to the clutch on revs that fell faster than an engine let go
  // falls (toward idle within declutch_time) keeps the share of its pull by which they did, as its mean and
  // its spread: by that share the reading was off the engine's line (a tracker's lock on another order), not
  // a declutch, and the car pulls on (0: the pull ends at any fall, as a declutch ends it).
  double declutch_pull_spread = 1.0;
  // 1: a ladder that lacks first gear (first_gear_idle_speed) is extended below its lowest gear by the
  // gears a progressive gearbox has there, predicted from the ladder's own lowest steps, until the lowest
  // carries the car at the warm idle no faster than first gear does (0: none predicted).
  double predict_lower_gears = 1.0;
  // 1: a ladder that lacks first gear takes the gears below it that a plausible ladder of more gears held
  // in the fit (the model's extra.lower_gears) before any predicted from its steps (0: none taken).
  double fitted_lower_gears = 1.0;
  // 1: a step of the model's ladder twice the step above it or more lacks the gears a progressive gearbox
  // has there (its steps do not shrink toward the low gears), predicted from the steps above (0: none).
  double fill_ladder_gaps = 1.0;
  // 1: the model's top step lacks gears where it is more than 1.5 times the step below it (steps shrink
  // toward the top gears), or, on a two-gear ladder, more than a factor of 2 (the largest gearbox step):
  // the fewest gears that make its steps no larger than that bound, at equal steps (0: none).
  double fill_top_step = 1.0;
  // 1: a gear predicted inside the ladder (fill_ladder_gaps, fill_top_step) is used as the less used of the
  // model's gears beside it: it lies among cruising gears and is no launch gear passed in a second (0: the
  // least share of use).
  double gap_gear_share = 1.0;
  // The factor by which the steps in a step of the ladder lacking gears (fill_ladder_gaps) grow from one
  // gear to the next lower where no step above the step above it measures it: the geometric middle of the
  // range a progressive gearbox's steps grow within (1 to 1.5), sqrt 1.5.
  double gap_step_growth = 1.2247;
  // 1: the gears below the ladder's lowest measured gear are also as many as the launches from rest seen
  // under GPS show, by the upshifts they make before the filter holds that gear (launch_gears.hpp); each
  // launch's count is off by one with the share launch_second (0: the idle alone decides).
  double launch_gears = 1.0;
  // 1: the launches start from those the fit counted in its log (extra.launch_gears), by the same rule on
  // its rows (two in a row on a gear's line stand for the filter's confident belief): a drive's first
  // outage may come before its first launch, or in a jam whose crawls in first gear never reach the next
  // (0: from the launches seen under GPS on this drive alone).
  double fit_launch_gears = 1.0;
  // Gears predicted above the model's top gear, at most (0: none): a young model has not yet cruised in
  // the tall gears. Each is the next step of a gearbox whose steps shrink toward the top, from the model's
  // own top steps, while the highest carries the car at the warm idle slower than top_gear_idle_speed.
  double predict_upper_gears = 1.0;
  // m/s: the most a top gear carries a car at idle (the tallest top gears of manual boxes, about 60 km/h per
  // 1000 rpm, at an idle of 700-800 rpm: 12-13 m/s).
  double top_gear_idle_speed = 12.0;
  // 1: gears are predicted above a model's top gear only where its fit saw that gear run no higher than the
  // gear below it (extra.revs, the upper ends of their bands): a driver leaves a gear for the next before
  // the revs pass his usual band, so a gear run higher than the one below it had no gear above to be left
  // for; and the predicted gear runs in the top gear's band, without which it takes a car rolling at idle
  // revs as cruising (0: whatever the revs; the driver's revs at large for the predicted gear).
  double top_gear_revs = 1.0;
  // Pairs: gears are predicted above a model's top gear only while its fit saw that gear on fewer pairs
  // than this. A driver with a gear above the top one seen shifts into it within minutes of cruising on an
  // open road; 300 pairs are five minutes at the daemon's 1 Hz fixes (ten at 2 s rows). Beyond that the top
  // gear seen is the gearbox's (infinity: however long it was driven).
  double upper_gear_samples = 300.0;
  // A young fit's idle is a cold engine's: its standing pairs come from the first minutes of a first drive,
  // when the engine idles high, as does the idle learned then under GPS, and a car that does not stop
  // again under GPS keeps it. While the model's fit used fewer than warm_fit_samples pairs (20 minutes at
  // the daemon's 1 Hz fixes, several times an engine's warm-up), revs down to the idle learned over
  // cold_idle_ratio (a cold engine's fast idle, up to half above its warm idle) are idle too: a warming
  // engine's idle only falls (1: only revs down to the idle learned, or the fit's). The bound counts pairs,
  // as the fit records them: a log fitted offline at 5 s rows stays young for 100 minutes of rows.
  double cold_idle_ratio = 1.5;
  double warm_fit_samples = 1200.0;
  // 1: a GPS fix is the speed of a moment before the step it comes with, as late against the revs as
  // SpeedLag learns from this drive's fixes (0: the speed of the step itself).
  double speed_lag = 1.0;
  // 1: until the drive's fixes show their own lag significantly, it is the lag the fit found between
  // the speeds and the revs (the model's extra.speed_lag) (0: 0 s).
  double speed_lag_prior = 1.0;
  // Standard errors by which the drive's own lag must beat the prior's before it is used (0: the best
  // candidate from the first fix that tells them apart).
  double speed_lag_significance = SpeedLag::kSignificance;
};

}  // namespace gearpulse
