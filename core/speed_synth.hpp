#pragma once
// Speed synthesis: turns a causal stream of (time, GPS speed or none, engine frequency or none) into the
// speed the pulse output carries. While GPS is present it outputs the GPS speed and tracks the engaged
// gear; through a GPS outage it outputs theta_gear x frequency, following shifts (a jump of frequency
// while speed stays continuous), coasting through clutch-out moments and coming to zero at a stop.
//
// The gear is tracked over the modes {clutch out, gear 1..M} by a causal max-product (Viterbi) recursion
// in which every mode keeps the best history that ends in it, with that history's own speed track (so
// competing gear hypotheses survive until a later shift or stop tells them apart, and a hypothesis pays
// for the speed jump it implies when it is entered, once): evidence for a gear is how well theta_i x freq
// continues the speed with a plausible acceleration (with GPS: how well it matches the GPS speed);
// evidence for clutch-out is the density of the engine frequency when declutched, a spike at the idle
// frequency (learned while GPS says the car stands still) over a flat floor. The output follows the most
// probable mode. No look-ahead: every output depends only on past input.
//
// Real-time use: step() is noexcept and never allocates; all state lives in fixed arrays. set_model()
// copies the model's few numbers into those arrays, so a model can be swapped between any two steps.
#include <array>
#include <cstdint>
#include <memory>
#include <string_view>

#include "core/gear_model.hpp"

namespace gearpulse {

enum class SpeedSource : std::uint8_t { kNone, kGps, kEngine, kCoast };

// "none", "gps", "engine", "coast" (the `source` column of `gearpulse replay`).
[[nodiscard]] std::string_view source_name(SpeedSource source) noexcept;

struct SynthOutput {
  double speed = 0.0;  // m/s, >= 0; what the pulse output carries
  int gear = 0;        // 1 = lowest; 0 = none/unknown (clutch out, standing, no model)
  SpeedSource source = SpeedSource::kNone;
};

// Driving-physics constants (not from the paper): plausible accelerations of a road car and how often a
// driver shifts. They are deliberately generic, not fitted to any one log.
struct SynthTuning {
  double accel_sigma = 0.7;   // m/s^2: how far a driver's acceleration strays from its trend in 1 s
  double max_accel = 3.5;     // m/s^2: bound on the acceleration trend
  double launch_accel = 2.5;  // m/s^2: the output rises no faster (clutch slip when moving off)
  double accel_time = 2.0;    // s: time constant of the acceleration trend
  double trend_keep = 0.5;    // share of the acceleration trend expected to go on over a step
  double trend_up = 1.0;
  double shift_coast_decel = 0.3;  // m/s^2: rolling resistance + drag while declutched during a shift
  double stop_decel_min = 0.4;     // m/s^2: at least this while declutched at idle (braking to a stop)
  double stop_decel_max = 2.5;     // m/s^2: at most this (a firm but ordinary stop)
  double gear_leave_rate = 0.15;   // 1/s: rate of leaving a gear (shift or clutch-in) at ordinary rpm
  double clutch_leave_rate = 0.6;  // 1/s: rate of engaging a gear after clutch-out
  double idle_weight = 0.6;        // share of the declutched frequency density in the idle spike
  double lugging_first = 0.2;      // relative chance of first gear with the engine at idle (creeping)
  double lugging_other = 0.05;     // same for higher gears: drivers do not lug an engine at idle
  double min_speed_sigma = 0.15;   // m/s: floor on the model's sigma_v (integer km/h logs, GPS noise)
  double min_freq_rel = 0.01;      // floor on sigma_s as a fraction of the frequency (tracking jitter)
  double stationary_speed = 0.3;   // m/s: GPS speed below this is "standing" (idle is learned there)
  double max_gap = 30.0;           // s: a longer gap between steps forgets the speed track
};

class SpeedSynthesizer {
 public:
  static constexpr int kMaxGears = 12;

  explicit SpeedSynthesizer(std::shared_ptr<const GearModel> model = nullptr, const SynthTuning& tuning = {});

  // Swaps the model between steps (no allocation). Output stays continuous: the speed tracks are kept and
  // the gear belief is carried over to the new model's nearest gears. Returns false, and keeps the old
  // model, if the new one has more than kMaxGears gears.
  bool set_model(std::shared_ptr<const GearModel> model) noexcept;
  [[nodiscard]] const std::shared_ptr<const GearModel>& model() const noexcept { return model_; }

  // One causal step. gps_speed: m/s or NaN when there is no fresh fix; freq: Hz or NaN when not tracked.
  // t must not decrease (a step back in time is treated as no time passing).
  SynthOutput step(double t, double gps_speed, double freq) noexcept;

  // Forget all state except the model (e.g. after the engine was off).
  void reset() noexcept;

  [[nodiscard]] const SynthOutput& last() const noexcept { return last_; }
  // Current belief in a mode: 0 = clutch out, 1..gears = that gear (0 for gears the model lacks).
  [[nodiscard]] double mode_probability(int mode) const noexcept {
    return mode >= 0 && mode <= gears_ ? prob_[static_cast<std::size_t>(mode)] : 0.0;
  }
  // Learned idle frequency (Hz), NaN until GPS has seen the car standing with the engine tracked.
  [[nodiscard]] double idle_freq() const noexcept;

 private:
  static constexpr int kModes = kMaxGears + 1;  // mode 0 = clutch out
  using ModeArray = std::array<double, kModes>;

  void load_model(const GearModel* model) noexcept;
  void compute_transitions(double dt, double freq) noexcept;
  SynthOutput gps_step(double dt, double gps, double freq) noexcept;
  SynthOutput engine_step(double dt, double freq) noexcept;
  [[nodiscard]] double clutch_likelihood(double freq) const noexcept;
  [[nodiscard]] double freq_sigma(double freq) const noexcept;
  [[nodiscard]] double idle_sd() const noexcept;
  [[nodiscard]] double lugging(int gear, double freq) const noexcept;
  [[nodiscard]] double shift_urge(double freq) const noexcept;
  [[nodiscard]] double upshift_factor(double freq) const noexcept;
  [[nodiscard]] double downshift_factor(double freq) const noexcept;
  void learn_shift(double freq) noexcept;
  [[nodiscard]] int map_mode() const noexcept;
  void learn(double dt, double gps, double freq) noexcept;
  void update_accel(double dt, double speed) noexcept;
  void normalise() noexcept;

  SynthTuning tuning_;
  std::shared_ptr<const GearModel> model_;
  int gears_ = 0;
  ModeArray theta_{};
  ModeArray weight_{};      // stationary share of each mode (mode 0 = clutch out)
  ModeArray leave_rate_{};  // 1/s, per gear
  double sigma_v_ = 0.0;
  double sigma_s_ = 0.0;

  ModeArray prob_{};           // forward probabilities of the modes
  ModeArray speed_{}, var_{};  // per-mode speed track (m/s) and its variance ((m/s)^2)
  ModeArray next_p_{}, next_v_{}, next_var_{};
  std::array<ModeArray, kModes> trans_{};  // trans_[i][j]: probability of mode i -> mode j over this step

  bool started_ = false;
  double t_ = 0.0;
  double out_speed_ = 0.0;
  double accel_ = 0.0;  // acceleration trend, m/s^2
  int mode_ = 0;        // current MAP mode
  double idle_mean_ = 0.0, idle_var_ = 0.0, idle_count_ = 0.0;
  double drive_mean_ = 0.0, drive_var_ = 0.0, drive_count_ = 0.0;  // engine frequency while in gear
  // Engine frequency just before this driver's up- and downshifts, seen while GPS was present.
  double up_mean_ = 0.0, up_var_ = 0.0, up_count_ = 0.0;
  double down_mean_ = 0.0, down_var_ = 0.0, down_count_ = 0.0;
  int sure_gear_ = 0;            // last gear held with confidence under GPS
  double sure_gear_freq_ = 0.0;  // its last frequency
  double freq_max_ = 0.0;        // highest frequency seen (flat part of the declutched density)
  SynthOutput last_{};
};

}  // namespace gearpulse
