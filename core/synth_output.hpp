#pragma once
// What SpeedSynthesizer outputs and how it chooses it (SynthOutputPolicy): under GPS the GPS speed;
// through an outage with a gear ladder, the speed of the mode at a quantile of the belief ordered by speed,
// leaning toward the contenders' speed, and rest for a declutched car slower than walking pace; without a
// ladder, the last GPS speed held for a while, then coming down to rest. No allocation.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

namespace gearpulse {

struct SynthTuning;

enum class SpeedSource : std::uint8_t { kNone, kGps, kEngine, kCoast };

// "none", "gps", "engine", "coast" (the `source` column of `gearpulse replay`).
[[nodiscard]] std::string_view source_name(SpeedSource source) noexcept;

// The speed a split belief's contenders point to: each speed weighted by the square of its probability.
// Between two modes this is the speed of least expected |error|^1.5, between the median's |error| and
// the mean's error^2: a contender holding a fifth of the belief moves it a seventeenth of the way to its
// own speed, one holding 0.4 against 0.6 a third of the way, so a mode that clearly leads keeps its speed.
// `prob` and `speed` have the same size; 0 if no mode holds any belief.
[[nodiscard]] double contended_speed(std::span<const double> prob, std::span<const double> speed) noexcept;

// The mode at quantile `q` of a belief ordered by speed: the first mode, slowest first, at which the belief
// in it and in every slower mode reaches q. Modes of equal speed (a negligible mode carries the leader's
// history) count as one, named by the most probable of them. A mode holding at least max(q, 1 - q) is its
// own quantile. q = 0.5 is the median, whose speed errs least in mean absolute terms where the belief is
// right about its odds; a higher q leans toward the faster modes. `prob` and `speed` have the same size,
// at most 16 modes; -1 if there are none.
[[nodiscard]] int belief_quantile_mode(std::span<const double> prob, std::span<const double> speed,
                                       double q) noexcept;

struct SynthOutput {
  double speed = 0.0;  // m/s, >= 0; what the pulse output carries
  int gear = 0;        // 1 = lowest; 0 = none/unknown (clutch out, standing, no model)
  SpeedSource source = SpeedSource::kNone;
  // m/s: the belief's spread about `speed` through an outage (each mode's speed uncertainty and how far the
  // modes' speeds lie from it, weighed by their belief); 0 while GPS gives the speed or nothing is known.
  double speed_sd = 0.0;
};

// How the output speed is chosen from the belief the filter holds, and held without a ladder.
class SynthOutputPolicy {
 public:
  static constexpr std::size_t kMaxModes = 16;  // the most modes outage() reads

  // The output through an outage with a ladder of `gears`: per mode (0 = declutched, 1..gears, gears + 1 =
  // moving off) its belief `prob`, its track's speed `speed` and that speed's variance `speed_var`;
  // `model_gear` names each gear of the ladder in the model (0: a gear the model lacks), `map_mode` is the
  // most probable mode.
  [[nodiscard]] static SynthOutput outage(std::span<const double> prob, std::span<const double> speed,
                                          std::span<const double> speed_var, int gears,
                                          std::span<const int> model_gear, int map_mode,
                                          const SynthTuning& tuning) noexcept;

  // A GPS speed seen at t, held through an outage without a ladder.
  void note_gps(double t, double gps) noexcept {
    held_speed_ = gps;
    held_t_ = t;
  }
  void forget_gps() noexcept { held_speed_ = -1.0; }
  // The output at t without a ladder (no model yet, an automatic or CVT): GPS's speed `gps` (NaN: none),
  // else the last one held for hold_time, then coming down to rest at coast_accel.
  [[nodiscard]] SynthOutput hold(double t, double gps, const SynthTuning& tuning) const noexcept;

 private:
  double held_speed_ = -1.0, held_t_ = 0.0;  // last GPS speed and its time (-1 = none yet)
};

}  // namespace gearpulse
