#pragma once
// A candidate outage synthesis, measured beside SpeedSynthesizer (speed_synth.hpp) by bench_outage and
// not yet used by the daemon or `gearpulse replay`. Same interface and contract as SpeedSynthesizer.
//
// It turns a causal stream of (time, GPS speed or none, engine frequency or none) into the
// speed the pulse output carries. While GPS is present it outputs the GPS speed, tracks the engaged mode
// and learns the driver's habits; through a GPS outage it outputs the mean speed of the mode filter's
// belief (ModeFilter: declutched, gear 1..M or moving off, each with its speed track), which minimises the
// expected error of the distance a navigator integrates from it. Without a gear ladder (no model yet, an
// automatic or CVT) the frequency says nothing of the speed: an outage holds the last GPS speed for kHoldTime
// (a tunnel's speed is most likely the speed going in), then comes down to rest at the coasting deceleration.
// No look-ahead: every output depends only on past input, and not on the rate of the steps.
//
// Real-time use: step() is noexcept and never allocates. set_model() copies the model's few numbers into
// fixed arrays, so a model can be swapped between any two steps.
#include <cstdint>
#include <memory>
#include <string_view>

#include "core/driving_habits.hpp"
#include "core/gear_model.hpp"
#include "core/mode_filter.hpp"
#include "core/sample.hpp"
#include "core/speed_synth.hpp"

namespace gearpulse {

class ImmSpeedSynthesizer {
 public:
  static constexpr int kMaxGears = static_cast<int>(GearModel::kMaxGears);
  static constexpr double kHoldTime = 60.0;  // s: an outage without a ladder holds the last GPS speed
  static constexpr double kMaxGap = 30.0;    // s: a longer gap between steps forgets the speed
  static constexpr double kStanding = 0.3;   // m/s: a GPS speed below this is standing
  static constexpr double kSure = 0.8;       // belief in a mode under GPS for its habits to be learned

  explicit ImmSpeedSynthesizer(std::shared_ptr<const GearModel> model = nullptr);

  // Swaps the model between steps (no allocation). The speed tracks and the habits learned are kept and
  // the belief in each gear moves to the new ladder's nearest gear. Returns false, and keeps the old model,
  // if the new one has more than kMaxGears gears.
  bool set_model(std::shared_ptr<const GearModel> model) noexcept;
  [[nodiscard]] const std::shared_ptr<const GearModel>& model() const noexcept { return model_; }

  // One causal step. gps_speed: m/s or NaN when there is no fresh fix; freq: Hz or NaN when not tracked.
  // t must not decrease (a step back in time is treated as no time passing). gps_new: the fix has not
  // been given to an earlier step; a live caller steps at every tracker hop and passes the newest fresh
  // fix each time, measured once.
  SynthOutput step(double t, double gps_speed, double freq, bool gps_new = true) noexcept;

  // Forget all state except the model and the habits learned (e.g. after the engine was off).
  void reset() noexcept;

  [[nodiscard]] const SynthOutput& last() const noexcept { return last_; }
  // Current belief in a mode: 0 = no gear engaged, 1..gears = that gear (0 for gears the model lacks).
  [[nodiscard]] double mode_probability(int mode) const noexcept;
  // Learned idle frequency (Hz), NaN until known.
  [[nodiscard]] double idle_freq() const noexcept { return learner_.habits().idle; }
  [[nodiscard]] const DrivingHabits& habits() const noexcept { return learner_.habits(); }
  [[nodiscard]] const ModeFilter& filter() const noexcept { return filter_; }

 private:
  SynthOutput hold_step(double t, double gps) const noexcept;
  void learn(double dt, double gps, bool gps_new, double freq) noexcept;

  std::shared_ptr<const GearModel> model_;
  int gears_ = 0;
  ModeFilter filter_;
  HabitLearner learner_;
  bool started_ = false;
  bool informed_ = false;  // a GPS fix or a frequency reading has been seen since reset()
  double t_ = 0.0;
  double fix_speed_ = -1.0, fix_t_ = 0.0;    // the last fix measured, for the acceleration learned
  double held_speed_ = -1.0, held_t_ = 0.0;  // last GPS speed and its time, for hold_step (-1 = none yet)
  SynthOutput last_{};
};

// Steps a synthesizer over the samples of a log, in order, as `gearpulse replay` and the benches do. An OBD
// logger writes each value again on every row until its next poll: a sample that only repeats a held rpm
// (repeats_held_freq) answers with the last output instead of a step, a held speed is no new fix and a held
// rpm no new reading.
class ImmLogReplayer {
 public:
  explicit ImmLogReplayer(ImmSpeedSynthesizer& synth) noexcept : synth_(synth) {}

  const SynthOutput& step(const Sample& s) noexcept {
    if (repeats_held_freq(last_, s)) return out_;
    const bool new_fix = !(s.has_speed() && s.speed == fix_.speed && s.t - fix_.t <= kHeldSpan);
    const bool new_freq = !(s.has_freq() && s.freq == reading_.freq && s.t - reading_.t <= kHeldSpan);
    out_ = synth_.step(s.t, s.speed, new_freq ? s.freq : kMissing, new_fix);
    if (new_fix && s.has_speed()) fix_ = s;
    if (new_freq && s.has_freq()) reading_ = s;
    last_ = s;
    return out_;
  }

 private:
  ImmSpeedSynthesizer& synth_;
  Sample last_;     // the last sample stepped
  Sample fix_;      // the sample that brought the speed last measured
  Sample reading_;  // the sample that brought the frequency last read
  SynthOutput out_;
};

}  // namespace gearpulse
