#pragma once
// What SpeedSynthesizer knows of this engine and driver beyond the gear ladder: the idle (standing, and
// rolling declutched), the revs run in gear at large and in each gear of the ladder, how hard the car slows
// declutched (at large, and with the engine at idle), and the revs at which this driver shifts up and down.
// Seeded from the fit (the model's extras: load_engine(), load_gear_revs()) and learned while GPS is present
// (learn(), learn_shift()) as running means with a bounded memory, so they follow a warming engine and a
// change of road. The queries turn them into what the filter asks: the idle band, the deceleration
// declutched, and how the revs move the hazards of a shift. Fixed arrays only: nothing here allocates.
#include <array>

#include "core/gear_model.hpp"
#include "core/model_extras.hpp"

namespace gearpulse {

struct SynthTuning;

class SynthHabits {
 public:
  // Per position of the synthesizer's ladder (1..gears; 0 and the slot past the top unused).
  static constexpr int kSlots = static_cast<int>(GearModel::kMaxGears) + 2;
  using GearArray = std::array<double, kSlots>;
  using GearNumbers = std::array<int, kSlots>;

  // What the fit saw of this engine and driver: the warm idle (also the idle until GPS shows this car
  // standing), the rolling idle and the deceleration declutched at idle until GPS shows them. Anything
  // missing or malformed is left unknown.
  void load_engine(const ModelExtras& extras, const SynthTuning& tuning) noexcept;
  // The revs the fit saw run in each gear of a ladder of `gears`, whose positions carry the model's gear
  // numbers `model_gear` (0: a gear the model lacks), once the ladder is built.
  void load_gear_revs(const ModelExtras& extras, const GearNumbers& model_gear, int gears) noexcept;
  // The gear at position `to` is run as the one at `from` is (its revs band), once load_gear_revs has run.
  void share_gear_revs(int from, int to) noexcept {
    revs_mean_[to] = revs_mean_[from], revs_sd_[to] = revs_sd_[from], revs_count_[to] = revs_count_[from];
  }

  // Under GPS, after a step of dt ending at t: GPS speed `gps` (a new fix if gps_new), frequency `freq`
  // (NaN if lost); the filter's most probable mode `mode` (0 = declutched) holding `belief`, `in_gear`
  // whether it is a gear, and `at_idle` whether the frequency is at idle (at_idle()).
  void learn(double t, double dt, double gps, double freq, bool gps_new, int mode, bool in_gear,
             double belief, bool at_idle, const SynthTuning& tuning) noexcept;
  // Under GPS, after each step: notes the frequency at which a confidently held gear (`gear` held with
  // `belief`; 0 = no gear) was left for its neighbour.
  void learn_shift(int gear, double belief, double freq) noexcept;
  // Under GPS, after each step of dt: the filter's most probable mode `mode` (0 = declutched) holding
  // `belief`, whether it is a gear (`in_gear`) that pulls (`pulling`), and whether the car rolls. Of the
  // gears left while they pulled, counts where the next gear held with confidence was: the one above, the
  // same (after a declutch of at most `max_declutch` s) or another.
  void learn_pulled_shift(int mode, double belief, bool in_gear, bool pulling, bool rolling, double dt,
                          double max_declutch) noexcept;
  // Share of the declutches after a pulling gear that engage the gear above: the Laplace (add-one)
  // estimate over the three outcomes of learn_pulled_shift, over about the last kPulledShiftMemory.
  [[nodiscard]] double upshift_share() const noexcept {
    return (pulled_count_[kUpOne] + 1.0) /
           (pulled_count_[kUpOne] + pulled_count_[kSame] + pulled_count_[kOther] + 3.0);
  }
  static constexpr double kPulledShiftMemory = 50.0;  // shifts
  // No shift is pending across a reset or a gap.
  void forget_pulled_shift() noexcept {
    pulled_gear_ = 0;
    pulled_declutch_ = 0.0;
    pulled_left_ = false;
  }

  // The next fix starts afresh (after a reset or a gap): no speed before it to measure a deceleration by.
  void forget_last_fix() noexcept { last_gps_ = from_gps_ = -1.0; }
  // A flat stretch of revs counts only if GPS saw it whole (rolling idle).
  void end_flat_stretch() noexcept { roll_span_ = -1.0; }
  // The ladder changed: the gear at old position i is at position to[i] (0 = gone), for old positions
  // 1..old_gears; or, with a new model of another ladder, the shift revs per gear are forgotten.
  void renumber_gears(const GearNumbers& to, int old_gears) noexcept;
  void forget_gear_shifts() noexcept;

  [[nodiscard]] bool idle_known() const noexcept { return idle_count_ > 0.0; }
  [[nodiscard]] double idle_mean() const noexcept { return idle_mean_; }
  // Learned idle frequency (Hz), NaN until known.
  [[nodiscard]] double idle_freq() const noexcept;
  [[nodiscard]] double idle_sd() const noexcept;
  // Idle of the warm engine (the fit's, over many stops); NaN if unknown.
  [[nodiscard]] double warm_idle() const noexcept { return warm_idle_; }
  [[nodiscard]] double rolling_idle(const SynthTuning& tuning) const noexcept;
  // Whether this frequency is at idle: below the rolling idle plus idle_braking::kBandSds idle spreads.
  [[nodiscard]] bool at_idle(double freq, const SynthTuning& tuning) const noexcept;
  // Whether a ladder whose lowest gear has `lowest_theta` lacks first gear (it carries the car at the warm
  // idle faster than any first gear does); false while no idle is known.
  [[nodiscard]] bool lacks_first_gear(double lowest_theta, const SynthTuning& tuning) const noexcept;
  // m/s: the speed a gear of `theta` carries the car at at the warm idle (the lower of the idle learned and
  // the fit's); NaN while no idle is known.
  [[nodiscard]] double idle_speed(double theta) const noexcept;
  // m/s^2: the mean deceleration declutched on the move (at_idle: with the engine at idle), before the
  // last metres' braking to a stop.
  [[nodiscard]] double coast_accel(bool at_idle, const SynthTuning& tuning) const noexcept;

  // Scores `freq` in each gear 1..gears by how usual it is there against gears at large, weighed by their
  // use `weight` (0 for every gear when the revs per gear are unknown): into `out`.
  void score_revs(double freq, const GearArray& weight, int gears, const SynthTuning& tuning,
                  GearArray& out) const noexcept;
  // How much likelier a shift from `from` (theta_from) to `to` (theta_to) at `freq` is for bringing the revs
  // nearer the band this driver runs the new gear in.
  [[nodiscard]] double shift_comfort(int from, int to, double theta_from, double theta_to, double freq,
                                     const SynthTuning& tuning) const noexcept;
  // Share (0..1) of the chance of a gear at `freq` that is lugging it, for a ladder of `gears`: revs below
  // those this driver holds any gear above first at (lugged_band()). 0 while no idle is known.
  [[nodiscard]] double lugged(double freq, int gears, const SynthTuning& tuning) const noexcept;
  // Hazard multipliers of shifting up or down out of `gear` at `freq`.
  [[nodiscard]] double upshift_factor(int gear, double freq, const SynthTuning& tuning) const noexcept;
  [[nodiscard]] double downshift_factor(int gear, double freq, bool long_step,
                                        const SynthTuning& tuning) const noexcept;

 private:
  [[nodiscard]] double revs_z(int gear, double freq) const noexcept;
  // The band of lugging revs: its top in ln(freq) and the spread (ln(freq)) its edge is soft over.
  struct LuggedBand {
    double top = 0.0, sd = 0.0;
  };
  [[nodiscard]] LuggedBand lugged_band(int gears, const SynthTuning& tuning) const noexcept;
  [[nodiscard]] double shift_urge(double freq) const noexcept;

  double idle_mean_ = 0.0, idle_var_ = 0.0, idle_count_ = 0.0;
  double warm_idle_ = 0.0;     // NaN if unknown (load_engine())
  bool idle_readable_ = true;  // readings can show the idle (SynthTuning::reading_floor)
  // Per gear, the log engine frequency this driver runs at (the model's extra.revs; sd 0 = unknown).
  GearArray revs_mean_{}, revs_sd_{};
  GearArray revs_count_{};                                         // samples the fit saw each gear's revs on
  double drive_mean_ = 0.0, drive_var_ = 0.0, drive_count_ = 0.0;  // engine frequency while in gear
  double coast_mean_ = 0.0, coast_count_ = 0.0;  // acceleration declutched and moving, seen under GPS
  double idle_coast_mean_ = 0.0, idle_coast_count_ = 0.0;  // the same with the engine at idle
  // Engine frequency rolling declutched above the standing idle (rolling_idle()): its mean, the s seen,
  // and the current flat stretch (s, -1 = none; its first frequency and GPS speed).
  double roll_mean_ = 0.0, roll_count_ = 0.0, roll_time_ = 0.0;
  double roll_span_ = -1.0, roll_freq_ = 0.0, roll_speed_ = 0.0;
  double last_gps_ = -1.0;  // newest fix (-1 = none)
  double from_gps_ = -1.0;  // the fix a deceleration is measured from (-1 = none to measure from)
  double from_t_ = 0.0;     // its step time
  // Engine frequency just before this driver's up- and downshifts, seen while GPS was present.
  double up_mean_ = 0.0, up_var_ = 0.0, up_count_ = 0.0;
  double down_mean_ = 0.0, down_var_ = 0.0, down_count_ = 0.0;
  GearArray gear_up_mean_{}, gear_up_var_{}, gear_up_count_{};  // the same, per gear left
  GearArray gear_down_mean_{}, gear_down_var_{}, gear_down_count_{};
  int sure_gear_ = 0;            // last gear held with confidence under GPS
  double sure_gear_freq_ = 0.0;  // its last frequency
  // Where the gears left while pulling went, counts over a bounded memory; the gear held with confidence
  // last if it pulled then (0: none), whether it has been left for the clutch, and the s declutched since
  // (-1: the declutch was too long to be a shift).
  enum PulledOutcome : std::size_t { kUpOne, kSame, kOther };
  std::array<double, 3> pulled_count_{};
  int pulled_gear_ = 0;
  bool pulled_left_ = false;
  double pulled_declutch_ = 0.0;
};

}  // namespace gearpulse
