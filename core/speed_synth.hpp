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
// shifts down; out of first gear the sooner the longer it has lasted, since first gear is for moving off; out
// of a declutch that followed a pulling gear, into the gear above at the share of such declutches this driver
// ended there under GPS). A gear is scored by its innovation in its own units: within a dead zone of ordinary
// jitter it costs per second of time, beyond it the jump costs once, however often step() is called (at
// steps much shorter than an acceleration lasts, such a jump upward also reopens the acceleration, so that a
// ramp the history did not expect is paid once too), and a gear just entered is scored as one held; being
// declutched or moving off is scored per second, and so is how usual the revs are in a gear for this driver
// (the fit's revs per gear, model extra.revs): steady revs that several gears explain go, over time, to the
// gear this driver runs them in, and a shift is the likelier the nearer it brings the revs to the new gear's
// band. The idle may have fallen since GPS last showed it (a warming engine) as far as the fit's warm idle.
// At such short steps in an outage, too, the clutch keeps no speed history of its own while a gear outweighs
// it, and a clutch biting after a move-off may find the car faster than the move-off guessed. Apart from
// these, the result does not depend on the step rate. The output follows the mode at a quantile of the belief
// by speed a little above its median (the most probable one while it holds 0.6 of it), leaning halfway toward
// the contenders' speed. A GPS fix is taken as the speed of a moment before its step, as late against the
// revs as the drive's fixes show (speed_lag.hpp). No look-ahead: every output depends only on past input.
//
// The filter runs on the model's gears and on the gears it has measured under GPS that the model lacks: a
// steady ratio of GPS speed to revs off every gear of the model (seen_gears.hpp), carried, with its standard
// error in the gear's reading, until a model has that gear; such a gear has no number in the model, and an
// output in it says gear 0. So do the gears below a ladder that lacks first gear (a young model has not seen
// the launch gears steady): those a plausible ladder of more gears held in the fit (extra.lower_gears),
// then the ones predicted from the ladder's own steps, as many as the idle and the launches from rest seen
// under GPS show (launch_gears.hpp).
//
// This file is the mode filter: its state and the step's handling of time and tracker gaps are in
// speed_synth.cpp, one step of the filter in synth_step.cpp, its mode changes in synth_rates.cpp, the scores
// of the frequency in each mode in synth_evidence.cpp, its ladder in synth_ladder.cpp (the gears that join it
// in synth_ladder_insert.cpp), and its constants are SynthTuning (synth_tuning.hpp). What it learns of the
// engine and driver is SynthHabits (synth_habits.hpp), and how its output is chosen from the belief is
// SynthOutputPolicy (synth_output.hpp).
//
// Real-time use: step() is noexcept and never allocates; all state lives in fixed arrays. set_model()
// copies the model's few numbers into those arrays, so a model can be swapped between any two steps.
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string_view>

#include "core/gear_model.hpp"
#include "core/launch_gears.hpp"
#include "core/model_extras.hpp"
#include "core/sample.hpp"
#include "core/seen_gears.hpp"
#include "core/speed_lag.hpp"
#include "core/synth_habits.hpp"
#include "core/synth_output.hpp"
#include "core/synth_tuning.hpp"

namespace gearpulse {

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
  // s: how much older than its step the speed of a fix given with `gps_age` is, as the steps correct for
  // it: measured_fix_lag(), or 0 with the rule off.
  [[nodiscard]] double fix_lag(double gps_age) const noexcept {
    return tuning_.speed_lag > 0.0 ? measured_fix_lag(gps_age) : 0.0;
  }
  // s: the same lag as measured, whether or not the steps correct for it (the speed lag against the stamps
  // plus the age, at least 0).
  [[nodiscard]] double measured_fix_lag(double gps_age) const noexcept {
    return std::max(0.0, speed_lag_.lag() + gps_age);
  }

  // Forget all state except the model, the gears measured under GPS that it lacks, and what was learned of
  // the feed (the receiver's and the logger's, not the drive's): the speed lag and the mean interval between
  // readings of the revs (e.g. after the engine was off).
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
  // Returns the ladder position the gear took (0: none, the ladder is full).
  int insert_in_ladder(double theta, double theta_se, double weight, int model_gear) noexcept;
  void insert_fitted_lower_gears() noexcept;
  [[nodiscard]] int predict_lower_gears(int base, ModeArray& theta) const noexcept;
  void insert_below_ladder(std::span<const double> thetas) noexcept;
  void shift_ladder(int from, int by) noexcept;
  void insert_predicted_gears() noexcept;
  [[nodiscard]] int predict_upper_gears(ModeArray& theta) const noexcept;
  void insert_upper_gears() noexcept;
  void read_top_gear_revs() noexcept;
  void change_ladder(bool new_model) noexcept;
  void observe_gear(double gps, double freq, double lag) noexcept;
  void observe_launch(double gps, double freq, bool gps_new) noexcept;
  // The model's number of a gear of the ladder (0: a gear seen under GPS that the model lacks, or no gear).
  [[nodiscard]] int model_gear(int mode) const noexcept { return is_gear(mode) ? model_gear_[mode] : 0; }
  [[nodiscard]] int launch_mode() const noexcept { return gears_ + 1; }
  [[nodiscard]] bool is_gear(int mode) const noexcept { return mode >= 1 && mode <= gears_; }
  // The time a fix given at this step with `gps_age` is stamped with (step's gps_age).
  [[nodiscard]] double fix_stamp(double gps_age) const noexcept { return t_ - gps_age; }
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
  void gear_transitions(int from, double dt, double freq, ModeArray& row,
                        double& caught_share) const noexcept;
  void clutch_transitions(double dt, double speed, ModeArray& row) const noexcept;
  void launch_transitions(double dt, ModeArray& row) const noexcept;
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
  void note_pulled(double dt) noexcept;
  // A gear's track pulls: its acceleration more than one of its spreads above 0 (pulled_engage).
  [[nodiscard]] static bool pulling(const Track& x) noexcept { return x.a > 0.0 && x.a * x.a > x.paa; }
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
  // The ladder's lowest gear carries the car at the warm idle faster than any first gear does, and the
  // launches seen under GPS do not show it is first after all (none upshifts before it: a motorcycle's
  // high idle, a tall first; launch_gears.hpp).
  [[nodiscard]] bool lacks_first_gear() const noexcept {
    return gears_ >= 1 && habits_.lacks_first_gear(theta_[1], tuning_) &&
           !(tuning_.launch_gears > 0.0 && launches_.gears_below(theta_[1], 1, tuning_.launch_second) == 0);
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
  bool young_idle_ = false;           // the fit's idle may be a cold engine's (SynthTuning::cold_idle_ratio)
  SeenGears seen_;
  LaunchGears launches_;       // how many gears the launches seen under GPS pass below the lowest measured
  double launch_revs_ = 0.0;   // Hz: the revs last read, for the launches
  double launch_speed_ = 0.0;  // m/s: the GPS speed of the last step
  double launch_revs_t_ = std::numeric_limits<double>::infinity();  // s: when (+inf: never)
  double revs_interval_ = 0.0;  // s: the mean interval between readings of the revs (0: none yet)
  // The newest fix not yet taught to speed_lag_: its stamp (s; +inf: none) and speed.
  struct UnlearnedFix {
    double t = std::numeric_limits<double>::infinity();
    double speed = 0.0;
  } unlearned_fix_;
  SpeedLag speed_lag_;      // how late GPS speed is against the revs, learned from the fixes
  ModeArray weight_{};      // share of each mode in use (0 = declutched; moving off has none)
  ModeArray leave_rate_{};  // 1/s, per gear
  ModeArray creep_{};       // 1: a gear seen under GPS only at lugged revs (SeenGears::Gear::creep)
  // Per gear, the share of the clutch's belief that came from it while it pulled, fading over the time spent
  // declutched (SynthTuning::pulled_engage).
  ModeArray pulled_{};
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
  bool at_idle_ = false;         // this step's frequency is at idle
  double fell_too_fast_ = 0.0;   // share by which this step's revs fell faster than an engine let go
  double lugged_ = 0.0;          // share of a gear's chance at this step's frequency that is lugging it
  double prev_freq_ = 0.0;       // frequency of the previous step (NaN if lost): the revs a shift left
  double freq_seen_t_ = 0.0;     // time of the latest frequency reading (-inf before the first)
  double lost_for_ = 0.0;        // s since then at this step, 0 with a reading
  double fix_measured_t_ = 0.0;  // stamp of the latest fix measured (-inf before the first)
  // s: the spacing of the readings the filter is fed at (the tracker's hop, a log's row): the step's own
  // length, or after a tracker gap taken as one step (gap_one_step), the hop before the gap.
  double hop_ = 0.0;
  bool in_gap_ = false;       // the hops since the last step were a tracker gap, not stepped
  double climb_ = 0.0;        // how fast the revs climb this step, 0..1 (filter_step)
  SynthOutputPolicy output_;  // how the output is chosen from the belief, and held without a ladder
  SynthOutput last_{};
};

// Steps a synthesizer over the samples of a log, in order, as `gearpulse replay` and the benches do: a
// sample that only repeats a held rpm (repeats_held_freq) answers with the last output instead of a step,
// and a speed that repeats the last fix within kHeldSpan is that fix held, not measured again (as the
// daemon holds a fix over the tracker's hops until the next, and a logger its last value).
class LogReplayer {
 public:
  explicit LogReplayer(SpeedSynthesizer& synth) noexcept : synth_(synth) {}

  const SynthOutput& step(const Sample& s) noexcept {
    if (!repeats_held_freq(last_, s)) {
      const bool new_fix = !(s.has_speed() && s.speed == fix_.speed && s.t - fix_.t <= kHeldSpan);
      out_ = synth_.step(s.t, s.speed, s.freq, new_fix);
      if (new_fix && s.has_speed()) fix_ = s;
      last_ = s;
    }
    return out_;
  }

 private:
  SpeedSynthesizer& synth_;
  Sample last_;  // the last sample stepped
  Sample fix_;   // the last sample whose speed was a new fix
  SynthOutput out_;
};

}  // namespace gearpulse
