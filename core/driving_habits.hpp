#pragma once
// What the outage synthesis knows of a car and its driver beyond the gear ladder, as data: how hard the car
// accelerates, how it slows with the clutch out, its idle, how long each gear is held and where a shift
// goes, and at which revs this driver runs. Each starts from a physical prior (the values below, each with
// its argument) worth a few observations, and is refined from the driving seen while GPS is present, when
// the engaged mode is known (HabitLearner). Nothing here is fitted to any one log.
#include <array>
#include <cmath>

#include "core/gear_model.hpp"

namespace gearpulse {

// Modes of the drivetrain: 0 = declutched (clutch out, neutral, standing), 1..M = gear, M + 1 = moving off
// (the clutch slipping from standstill).
inline constexpr int kMaxModes = static_cast<int>(GearModel::kMaxGears) + 2;
using ModeArray = std::array<double, kMaxModes>;

// Where a gear is left for, as shares of all the times it is left.
enum class ShiftKind : int { kUp, kDown, kSkipUp, kSkipDown, kDeclutch };
inline constexpr int kShiftKinds = 5;

struct DrivingHabits {
  double accel_sd = 1.0;       // m/s^2: stationary spread of the acceleration in gear
  double accel_time = 3.0;     // s: how long an acceleration persists (a driver's pedal, not a measurement)
  double coast_accel = -0.5;   // m/s^2: mean acceleration declutched and moving (rolling drag and brakes)
  double coast_sd = 1.0;       // m/s^2: its spread
  double idle = NAN;           // Hz, NaN until known
  double idle_sd = NAN;        // Hz
  double revs_mean = NAN;      // mean log engine frequency in gear (ln Hz), NaN until known
  double revs_sd = 0.35;       // sd of the log engine frequency in gear
  ModeArray gear_revs_mean{};  // per gear: mean log frequency this driver runs it at (the pooled band's
  ModeArray gear_revs_sd{};    // until the gear has been seen), and its sd
  // Share of the time in a gear above first spent with the revs at idle (lugging: the engine judders, so
  // drivers declutch or shift down); first gear creeps at idle as often as it likes.
  double lugging = 0.05;
  double freq_max = 0.0;   // Hz: the highest frequency seen; declutched revs are spread below 1.5x it
  ModeArray leave_rate{};  // 1/s: rate at which each gear (index 1..M) is left
  std::array<double, kShiftKinds> shift_share{};  // where a gear is left for (ShiftKind)
  double engage_rate = 1.0;                       // 1/s: declutched and moving -> a gear
  double launch_rate = 0.05;                      // 1/s: declutched and standing -> moving off
  double bite_rate = 0.7;     // 1/s: moving off -> the clutch has bitten (first or second gear)
  double launch_accel = 1.5;  // m/s^2: mean acceleration moving off
  double launch_sd = 0.8;     // m/s^2: its spread
};

// Learns DrivingHabits from steps whose mode and speed are known (GPS present, the filter sure of the mode).
// Every statistic is a count or a sum, so the habits are the same whatever the step rate.
class HabitLearner {
 public:
  HabitLearner() noexcept { reset(); }
  void reset() noexcept;
  // Seeds what the fit recorded (model extra: idle, revs per gear); keeps what was learned live.
  void seed_from(const GearModel& model) noexcept;

  // One step of dt seconds in `mode` (-1 = not sure; `launch` is the index of moving off), at GPS speed
  // `speed` (m/s), engine frequency `freq` (NaN = none). `accel` is the acceleration between the last two
  // fixes (NaN = none this step).
  void observe(double dt, int mode, int launch, double speed, double freq, double accel) noexcept;

  [[nodiscard]] const DrivingHabits& habits() const noexcept { return habits_; }

 private:
  void update() noexcept;

  struct Moments {
    double n = 0.0, mean = 0.0, m2 = 0.0;  // weight, mean, sum of squared deviations
    void add(double x, double w) noexcept;
    // As add(), the weight of what came before decaying with time constant `memory` (in units of w).
    void add_recent(double x, double w, double memory) noexcept;
    [[nodiscard]] double var() const noexcept { return n > 0.0 ? m2 / n : 0.0; }
  };

  DrivingHabits habits_;
  Moments accel_, coast_, idle_, revs_, launch_accel_;
  std::array<Moments, kMaxModes> gear_revs_{};
  ModeArray gear_time_{}, gear_leaves_{};
  std::array<double, kShiftKinds> shift_count_{};
  double moving_declutched_time_ = 0.0, moving_engages_ = 0.0;
  double standing_time_ = 0.0, launches_ = 0.0;
  double launch_time_ = 0.0, bites_ = 0.0;
  double upper_gear_time_ = 0.0, lugging_time_ = 0.0;
  int last_sure_ = -1;  // the last mode the learner was sure of
  bool last_standing_ = false;
  double freq_max_ = 0.0;
};

}  // namespace gearpulse
