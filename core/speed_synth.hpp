#pragma once
// Speed synthesis: turns a causal stream of (time, GPS speed or none, engine frequency or none) into the
// speed the pulse output carries. While GPS is present it outputs the GPS speed and tracks the engaged
// gear; through a GPS outage it outputs theta_gear x frequency, following shifts (a jump of frequency
// while speed stays continuous), coasting through clutch-out moments and coming to zero at a stop.
//
// The engaged mode is tracked over {declutched, gear 1..M, moving off} by a switching Kalman filter: every
// mode carries an estimate of the car's speed and acceleration (an Ornstein-Uhlenbeck acceleration, its
// covariance grown by the exact integrals, so many short steps equal one long one; in a gear the brakes may
// also go on within a step, a branch of the gear's history merged with the held one) and a belief; each step
// sums over the predecessors of every mode, predicted under that mode's motion and corrected by GPS and
// the frequency, and matches the mixture's first two moments (generalised pseudo-Bayes of order 2).
// In gear i the engine frequency is speed / theta_i (eq. (3)); declutched the car rolls and brakes and
// the engine falls to idle (learned while GPS says the car stands, or taken from the fit; rolling, the
// engine may be held above it, at a rolling idle learned while GPS shows the car slowing at flat revs that
// no gear explains) or runs free;
// moving off, the clutch slips and the car gains speed at a launch acceleration until first gear bites.
// Mode changes come from rates per second (up at the revs this driver shifts up, down at the revs he
// shifts down; out of first gear the sooner the longer it has lasted, since first gear is for moving off). A
// gear is scored by its innovation in its own units: within a dead zone of ordinary jitter it costs per
// second of time, beyond it the jump costs once, however often step() is called (at steps much shorter than
// an acceleration lasts, such a jump upward also reopens the acceleration, so that a ramp the history did not
// expect is paid once too), and a gear just entered is scored as one held; being declutched or
// moving off is scored per second, and so is how usual the revs are in a gear for this driver (the fit's revs
// per gear, model extra.revs): steady revs that several gears explain go, over time, to the gear this driver
// runs them in, and a shift is the likelier the nearer it brings the revs to the new gear's band. The idle
// may have fallen since GPS last showed it (a warming engine) as far as the fit's warm idle. At such short
// steps in an outage, too, the clutch keeps no speed history of its own while a gear outweighs it, and a
// clutch biting after a move-off may find the car faster than the move-off guessed. Apart from these, the
// result does not depend on the step rate. The output follows the mode at a quantile of the belief by speed a
// little above its median (the most probable one while it holds 0.6 of it), leaning halfway toward the
// contenders' speed. A GPS fix is taken as the speed of a moment before its step, as late against the revs
// as the drive's fixes show (speed_lag.hpp). No look-ahead: every output depends only on past input.
//
// The filter runs on the model's gears and on the gears it has measured under GPS that the model lacks: a
// steady ratio of GPS speed to revs off every gear of the model (seen_gears.hpp), carried, with its standard
// error in the gear's reading, until a model has that gear; such a gear has no number in the model, and an
// output in it says gear 0. So do the gears below a ladder that lacks first gear (a young model has not seen
// the launch gears steady): those a plausible ladder of more gears held in the fit (extra.lower_gears),
// then the ones predicted from the ladder's own steps, as many as the idle and the launches from rest seen
// under GPS show (launch_gears.hpp).
//
// This file is the mode filter: its step and motion are in speed_synth.cpp, its mode changes in
// synth_rates.cpp, the scores of the frequency in each mode in synth_evidence.cpp and its ladder in
// synth_ladder.cpp. What it learns of the engine and driver is SynthHabits (synth_habits.hpp), and how its
// output is chosen from the belief is SynthOutputPolicy (synth_output.hpp).
//
// Real-time use: step() is noexcept and never allocates; all state lives in fixed arrays. set_model()
// copies the model's few numbers into those arrays, so a model can be swapped between any two steps.
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>

#include "core/estimator.hpp"
#include "core/gear_model.hpp"
#include "core/launch_gears.hpp"
#include "core/model_extras.hpp"
#include "core/sample.hpp"
#include "core/seen_gears.hpp"
#include "core/speed_lag.hpp"
#include "core/synth_habits.hpp"
#include "core/synth_output.hpp"

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
  // loses to it at this rate. Tempered well below 1, since successive readings are far from independent.
  double revs_habit = 0.3;
  // Exponent on how much nearer a shift brings the revs to the band this driver runs the new gear in
  // (model extra.revs), as a factor on the rate of that shift; tempered as revs_habit is.
  double shift_comfort = 0.3;
  double min_speed_sigma = 0.15;  // m/s: floor on the model's sigma_v (integer km/h logs, GPS noise)
  double min_freq_rel = 0.01;     // floor on sigma_s as a fraction of the frequency (tracking jitter)
  double stationary_speed = 0.3;  // m/s: GPS speed below this is "standing" (idle is learned there)
  double max_gap = 30.0;          // s: a longer gap between steps forgets the speed track
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
  // gears steady): a move-off's clutch then bites in a gear
  // below the ladder, so its speed is not given the spread up to a gear's reading as it would be were
  // that gear first (bite_gap), and moving off stands for driving below the ladder, as plausible at speed
  // as at a walking pace (launch_fade does not apply) (inf: the lowest gear is always first).
  double first_gear_idle_speed = kFirstGearIdleSpeed;
  // Share of the deceleration a declutch carries that is its spread: with the clutch out the driver may
  // keep braking, ease off or stop braking (a downshift under braking), so the deceleration GPS measured
  // in gear is known no better than its own size once the clutch goes out. A gear the revs show next is
  // then entered from that spread of speeds, not from the braking carried on unchanged (0: the
  // deceleration stays as certain as GPS measured it).
  double declutch_brake_spread = 1.0;
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

class SpeedSynthesizer {
 public:
  static constexpr int kMaxGears = static_cast<int>(GearModel::kMaxGears);

  explicit SpeedSynthesizer(std::shared_ptr<const GearModel> model = nullptr, const SynthTuning& tuning = {});

  // Swaps the model between steps (no allocation). Output stays continuous: the speed tracks are kept and
  // the gear belief is carried over to the new model's nearest gears. Returns false, and keeps the old
  // model, if the new one has more than kMaxGears gears.
  bool set_model(std::shared_ptr<const GearModel> model) noexcept;
  [[nodiscard]] const std::shared_ptr<const GearModel>& model() const noexcept { return model_; }

  // One causal step. gps_speed: m/s or NaN when there is no fresh fix; freq: Hz or NaN when not tracked.
  // t must not decrease (a step back in time is treated as no time passing). gps_new: the fix has not
  // been given to an earlier step. A live caller steps at every tracker hop (10 per second and more) and
  // passes the newest fresh fix each time, one a second from most receivers: the repeats keep GPS the
  // source of the output but are not measured again (counted as ten independent readings a second, a
  // fix held the speed to a value up to a second old and pulled it back at every hop). gps_age: s by which
  // the time the fix is stamped with is older than t, where a caller stamps its fixes as it stamps the
  // pairs a model is fitted on (the daemon: receive time less gps.latency), so that the model's speed lag
  // is the fix's lag against its stamp, as it is against the step of its own row in a replayed log
  // (0, and the default: the fix is stamped t). Negative when the stamp is later than t (a live step's t is
  // its window's centre, older than the hop's processing, and a fix received meanwhile is newer): the lag
  // is then counted from t less that, at least 0, and the fix teaches the lag at the first step at or
  // after its stamp.
  SynthOutput step(double t, double gps_speed, double freq, bool gps_new = true,
                   double gps_age = 0.0) noexcept;
  // s: how much older than its step the speed of a fix given with `gps_age` is (the speed lag against the
  // stamps plus the age, at least 0; 0 with the rule off).
  [[nodiscard]] double fix_lag(double gps_age) const noexcept {
    return tuning_.speed_lag > 0.0 ? std::max(0.0, speed_lag_.lag() + gps_age) : 0.0;
  }

  // Forget all state except the model, the gears measured under GPS that it lacks, and the speed lag learned
  // (the receiver's and the logger's, not the drive's) (e.g. after the engine was off).
  void reset() noexcept;

  [[nodiscard]] const SynthOutput& last() const noexcept { return last_; }
  // Current belief in a mode: 0 = no gear engaged (declutched or moving off), 1..gears = that gear of the
  // model (0 for gears the model lacks).
  [[nodiscard]] double mode_probability(int mode) const noexcept;
  // Learned idle frequency (Hz), NaN until GPS has seen the car standing with the engine tracked.
  [[nodiscard]] double idle_freq() const noexcept;
  // For diagnostics: what the filter carries at a position of its ladder (0 = declutched, 1..ladder_gears()
  // the gears ascending, ladder_gears() + 1 = moving off): the speed (m/s), the acceleration (m/s^2) and
  // the acceleration's standard deviation.
  struct ModeTrack {
    double speed = 0.0, accel = 0.0, accel_sd = 0.0;
  };
  [[nodiscard]] ModeTrack mode_track(int position) const noexcept;
  [[nodiscard]] int ladder_gears() const noexcept { return gears_; }
  // For diagnostics: the theta of a gear of the ladder (1..ladder_gears(), ascending; 0 outside) and the
  // belief in a position of the ladder (as mode_track's positions).
  [[nodiscard]] double ladder_theta(int position) const noexcept {
    return position >= 1 && position <= gears_ ? theta_[static_cast<std::size_t>(position)] : 0.0;
  }
  [[nodiscard]] double position_probability(int position) const noexcept {
    return position >= 0 && position <= gears_ + 1 ? prob_[static_cast<std::size_t>(position)] : 0.0;
  }

 private:
  static constexpr int kModes = kMaxGears + 2;  // 0 = declutched, 1..gears, gears + 1 = moving off
  using ModeArray = std::array<double, kModes>;
  static_assert(kModes == SynthHabits::kSlots && kModes <= SynthOutputPolicy::kMaxModes);

  // Speed (m/s) and acceleration (m/s^2) with their covariance.
  struct Track {
    double v = 0.0, a = 0.0;
    double pvv = 1.0, pva = 0.0, paa = 1.0;
  };
  using TrackArray = std::array<Track, kModes>;

  static void keep_covariance(Track& x) noexcept;
  [[nodiscard]] static Track moment_match(const Track& x, double wx, const Track& y, double wy) noexcept;
  void load_model() noexcept;
  void insert_seen_gears() noexcept;
  void insert_gap_gears() noexcept;
  [[nodiscard]] bool seen_gear_near(double theta, double half) const noexcept;
  void insert_in_ladder(double theta, double theta_se, double weight, int model_gear) noexcept;
  void insert_fitted_lower_gears() noexcept;
  [[nodiscard]] int predict_lower_gears(int base, ModeArray& theta) const noexcept;
  void insert_below_ladder(std::span<const double> thetas) noexcept;
  void insert_predicted_gears() noexcept;
  [[nodiscard]] int predict_upper_gears(ModeArray& theta) const noexcept;
  void insert_upper_gears() noexcept;
  void read_top_gear_revs() noexcept;
  void change_ladder(bool new_model) noexcept;
  void observe_gear(double gps, double freq) noexcept;
  void observe_launch(double dt, double gps, double freq, bool gps_new) noexcept;
  // The model's number of a gear of the ladder (0: a gear seen under GPS that the model lacks, or no gear).
  [[nodiscard]] int model_gear(int mode) const noexcept { return is_gear(mode) ? model_gear_[mode] : 0; }
  [[nodiscard]] int launch_mode() const noexcept { return gears_ + 1; }
  [[nodiscard]] bool is_gear(int mode) const noexcept { return mode >= 1 && mode <= gears_; }
  // What one step of the filter gives every history it scores (filter_step, step_input).
  struct StepInput {
    double dt = 0.0;
    double gps = 0.0;   // m/s, NaN without a fix
    double freq = 0.0;  // Hz, NaN without a reading
    bool have_gps = false;
    bool measure_gps = false;  // a fix not measured at an earlier step
    bool short_step = false;   // the tracker's hops, not GPS or OBD rows
    bool lacks_first = false;  // lacks_first_gear()
    double weight = 0.0;       // share of a second of evidence this step carries
    double gps_var = 0.0;      // (m/s)^2: the fix's variance
    double lag = 0.0;          // s: how much older than the step the fix's speed is (fix_lag)
    double gained = 0.0;       // m/s: the filter's speed gained between the fix and the step before this one
    ModeArray revs_gain{};     // Hz gained in each gear within the step
  };

  void transitions_from(int from, double dt, double freq, double speed, ModeArray& row,
                        double& caught_share) const noexcept;
  void predict(Track& x, int to, double dt) const noexcept;
  [[nodiscard]] double log_evidence(Track& x, int mode, double freq, double weight,
                                    bool short_step) const noexcept;
  SynthOutput filter_step(double dt, double gps, double freq, bool gps_new, double gps_age) noexcept;
  [[nodiscard]] StepInput step_input(double dt, double gps, double freq, bool gps_new,
                                     double gps_age) const noexcept;
  void read_revs(const StepInput& in) noexcept;
  [[nodiscard]] Track entering(int i, int j, bool moving_off, bool have_gps) const noexcept;
  [[nodiscard]] Track propagate(const StepInput& in, Track y, int i, int j, bool moving_off, double caught,
                                double& score) const noexcept;
  [[nodiscard]] Track with_brakes(const StepInput& in, const Track& x, int j, Track held,
                                  double& score) const noexcept;
  void merge_histories(double dt) noexcept;
  void prune_histories(bool short_step, bool have_gps) noexcept;
  [[nodiscard]] double log_declutched(double freq, double speed) const noexcept;
  [[nodiscard]] double log_declutching(int gear, double freq, const Track& x) const noexcept;
  // The output at a hop of a tracker gap in an outage, `elapsed` s after the last step: the belief of that
  // step, every mode's track predicted over `elapsed` under its own motion.
  [[nodiscard]] SynthOutput in_gap_output(double elapsed) const noexcept;
  [[nodiscard]] double launch_plausibility(double speed) const noexcept;
  [[nodiscard]] double log_launch(double freq, double speed) const noexcept;
  [[nodiscard]] double freq_sigma(double freq) const noexcept;
  [[nodiscard]] double idle_sd() const noexcept { return habits_.idle_sd(); }
  [[nodiscard]] double rolling_idle() const noexcept { return habits_.rolling_idle(tuning_); }
  [[nodiscard]] double idle_ceiling() const noexcept;
  // The ladder's lowest gear carries the car at the warm idle faster than any first gear does.
  [[nodiscard]] bool lacks_first_gear() const noexcept {
    return gears_ >= 1 && habits_.lacks_first_gear(theta_[1], tuning_);
  }
  [[nodiscard]] double shift_comfort(int from, int to, double freq) const noexcept {
    return habits_.shift_comfort(from, to, theta_[from], theta_[to], freq, tuning_);
  }
  [[nodiscard]] double lugging(int gear) const noexcept;
  [[nodiscard]] int map_mode() const noexcept;
  void normalise() noexcept;

  SynthTuning tuning_;
  std::shared_ptr<const GearModel> model_;
  int gears_ = 0;
  // The ladder the filter runs on: the model's gears and the gears seen under GPS that it lacks
  // (seen_), ascending; per gear its theta, the standard error of it and its number in the model.
  ModeArray theta_{};
  ModeArray theta_se_{};
  std::array<int, kModes> model_gear_{};
  // How many of the ladder's lowest gears are predicted below the lowest known (insert_predicted_gears).
  int predicted_ = 0;
  // How many gears are predicted above the model's top gear (insert_upper_gears), and the thetas of the
  // upper_ of them that joined the ladder (a gear seen under GPS may stand for one).
  int predicted_above_ = 0;
  ModeArray upper_theta_{};
  int upper_ = 0;
  bool top_gear_below_band_ = false;  // the fit saw the model's top gear run no higher than the one below
  double top_gear_samples_ = 0.0;     // pairs the fit saw in the model's top gear (extra.revs)
  SeenGears seen_;
  LaunchGears launches_;  // how many gears the launches seen under GPS pass below the lowest measured
  // The newest fix not yet taught to speed_lag_: its stamp (s; +inf: none) and speed.
  struct UnlearnedFix {
    double t = std::numeric_limits<double>::infinity();
    double speed = 0.0;
  } unlearned_fix_;
  SpeedLag speed_lag_;      // how late GPS speed is against the revs, learned from the fixes
  ModeArray weight_{};      // share of each mode in use (0 = declutched; moving off has none)
  ModeArray leave_rate_{};  // 1/s, per gear
  double sigma_v_ = 0.0;
  double sigma_s_ = 0.0;

  ModeArray prob_{};  // max-product probabilities of the modes
  ModeArray age_{};   // s in each mode, averaged over the histories that hold it (0 when just entered)
  TrackArray track_{};
  ModeArray next_p_{};
  ModeArray row_{};                             // transition probabilities out of one mode over this step
  std::array<ModeArray, kModes> pair_score_{};  // log score of predecessor i -> mode j
  std::array<std::array<Track, kModes>, kModes> pair_track_{};  // the track it leads to

  bool started_ = false;
  bool informed_ = false;  // a GPS fix or a frequency reading has been seen since reset()
  double t_ = 0.0;
  int mode_ = 0;        // current MAP mode
  SynthHabits habits_;  // what this engine and driver do: learned under GPS, seeded by the fit
  ModelExtras extras_;  // what the fit recorded beside the model's ladder, read once per model
  // This step's log-score of the frequency in each gear by the revs this driver runs it at.
  ModeArray revs_habit_{};
  bool at_idle_ = false;      // this step's frequency is at idle
  double lugged_ = 0.0;       // share of a gear's chance at this step's frequency that is lugging it
  double prev_freq_ = 0.0;    // frequency of the previous step (NaN if lost): the revs a shift left
  double freq_seen_t_ = 0.0;  // time of the latest frequency reading (-inf before the first)
  double lost_for_ = 0.0;     // s since then at this step, 0 with a reading
  // s: the spacing of the readings the filter is fed at (the tracker's hop, a log's row): the step's own
  // length, or after a tracker gap taken as one step (gap_one_step), the hop before the gap.
  double hop_ = 0.0;
  bool in_gap_ = false;       // the hops since the last step were a tracker gap, not stepped
  double climb_ = 0.0;        // how fast the revs climb this step, 0..1 (filter_step)
  SynthOutputPolicy output_;  // how the output is chosen from the belief, and held without a ladder
  SynthOutput last_{};
};

// Steps a synthesizer over the samples of a log, in order, as `gearpulse replay` and the benches do: a
// sample that only repeats a held rpm (repeats_held_freq) answers with the last output instead of a step.
class LogReplayer {
 public:
  explicit LogReplayer(SpeedSynthesizer& synth) noexcept : synth_(synth) {}

  const SynthOutput& step(const Sample& s) noexcept {
    if (!repeats_held_freq(last_, s)) {
      out_ = synth_.step(s.t, s.speed, s.freq);
      last_ = s;
    }
    return out_;
  }

 private:
  SpeedSynthesizer& synth_;
  Sample last_;  // the last sample stepped
  SynthOutput out_;
};

}  // namespace gearpulse
