#pragma once
// The drivetrain-mode filter behind the outage synthesis: an interacting-multiple-model (IMM) filter over
// the modes {declutched, gear 1..M, moving off}, each carrying a Kalman estimate of the car's speed and
// acceleration.
//
// Motion: the acceleration is an Ornstein-Uhlenbeck process (mean 0 in gear, the learned coasting
// deceleration declutched and rolling, the learned launch acceleration moving off; spread and correlation
// time from DrivingHabits), integrated exactly over any step, so no car loses 16 km/h in 0.4 s and one step
// of 2 s equals twenty of 0.1 s. Mode changes: a continuous-time Markov chain whose rates are the learned
// habits (a gear is left at its leave rate, for the next gear up or down, a skip, or the clutch; declutched,
// a gear is engaged at the engage rate, the gear chosen by how well its revs at the current speed sit in this
// driver's band; standing, the car moves off at the launch rate and the clutch bites, in first gear or
// second, at the bite rate); the transition matrix over a step is exp(Q dt). Measurements: GPS speed (all
// modes); in gear i the engine frequency is v / theta_i (paper eq. (3)) with the fit's sigma_s (eq. (1)),
// theta's own standard error and a 1 % driveline slip; declutched the frequency says nothing of the speed and
// is spread as idle or anywhere below the revs seen; moving off, the revs are above idle and the engine turns
// faster than first gear would at the car's speed. The frequency has a small outlier share (a tracker hop on
// another line); GPS updates every mode in full. Readings of the revs closer than the evidence time apart are
// not independent (the tracker's window, the engine's slow wander): a step of dt weighs its frequency
// evidence by dt / evidence time, at most 1.
//
// Real-time use: step() is noexcept and never allocates; everything lives in fixed arrays.
#include <array>

#include "core/driving_habits.hpp"

namespace gearpulse {

struct SpeedTrack {
  double v = 0.0, a = 0.0;  // m/s, m/s^2
  double pvv = 100.0, pva = 0.0, paa = 1.0;
};

// The model's numbers the filter needs, per gear (index 1..gears; 0 unused).
struct GearLadder {
  int gears = 0;
  ModeArray theta{};          // (m/s)/Hz
  ModeArray theta_se{};       // standard error of theta
  double sigma_speed = 0.15;  // m/s, GPS speed noise (eq. (2))
  double sigma_freq = 0.3;    // Hz, tracker noise (eq. (1))
};

class ModeFilter {
 public:
  static constexpr double kEvidenceTime = 1.0;  // s

  // Forget everything: the speed unknown, the belief spread over the modes.
  void reset() noexcept;
  // A new ladder: the belief of each old gear moves to the new gear of nearest theta.
  void set_ladder(const GearLadder& ladder) noexcept;

  // One step of dt >= 0 seconds. gps: m/s or NaN; freq: Hz or NaN; evidence: the share of an independent
  // reading the frequency stands for (min(1, dt / kEvidenceTime); 1 for a first reading).
  void step(double dt, double gps, double freq, const DrivingHabits& habits, double evidence) noexcept;

  [[nodiscard]] double probability(int mode) const noexcept { return prob_[static_cast<std::size_t>(mode)]; }
  [[nodiscard]] const SpeedTrack& track(int mode) const noexcept {
    return track_[static_cast<std::size_t>(mode)];
  }
  [[nodiscard]] int modes() const noexcept { return ladder_.gears + 2; }
  [[nodiscard]] int launch() const noexcept { return ladder_.gears + 1; }
  [[nodiscard]] bool is_gear(int mode) const noexcept { return mode >= 1 && mode <= ladder_.gears; }
  [[nodiscard]] int most_probable() const noexcept;
  // The belief's mean speed: what minimises the expected error of the distance integrated from it.
  [[nodiscard]] double mean_speed() const noexcept;
  // The belief's spread (m/s) about a speed: each mode's own uncertainty and its distance from it.
  [[nodiscard]] double speed_spread(double about) const noexcept;

 private:
  using Matrix = std::array<ModeArray, kMaxModes>;
  struct Acceleration {
    double mean = 0.0, sd = 0.0;  // m/s^2
  };
  // The acceleration of a mode: mean 0 in gear, the coasting deceleration declutched (rolling), the launch
  // acceleration moving off; its stationary spread.
  [[nodiscard]] Acceleration acceleration(int mode, const DrivingHabits& habits) const noexcept;
  void transition_matrix(double dt, const DrivingHabits& habits) noexcept;
  [[nodiscard]] double entry_weight(int gear, double speed, const DrivingHabits& habits) const noexcept;
  void predict(SpeedTrack& x, int mode, double dt, const DrivingHabits& habits) const noexcept;
  [[nodiscard]] double update_gps(SpeedTrack& x, double gps) const noexcept;
  [[nodiscard]] double update_freq(SpeedTrack& x, int mode, double freq, double weight,
                                   const DrivingHabits& habits) const noexcept;

  GearLadder ladder_;
  ModeArray prob_{};
  std::array<SpeedTrack, kMaxModes> track_{};
  Matrix trans_{};    // trans_[i][j]: from i to j over this step
  Matrix scratch_{};  // for the matrix exponential
  Matrix power_{};
};

}  // namespace gearpulse
