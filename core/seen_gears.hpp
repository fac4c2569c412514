#pragma once
// Gears the synthesis measures under GPS that its model lacks. While GPS gives the speed and the engine
// frequency is tracked, the ratio v / f of a car in gear is that gear's theta (eq. (3)). A fix whose ratio
// agrees with the fix before it (the fit's steady-pair rule, steady_ratios_agree), at a speed that changed
// since by less than the fix's lateness (half a second at least) can bias a ratio by 1 % (2 % a second
// with GPS 0.5 s late or less, 1.1 % at 0.9 s), and that lies off every gear of the model (none
// within a gearbox step, a factor of 1.06) is a sighting of a gear the model lacks; sightings within half a
// gear window (kGearWindow) of each other are one gear. Once a gear has been sighted on `min_fixes` fixes in
// a row it is *seen*: its theta is the mean ratio of all its sightings, with the standard error of that mean,
// and its share of use that of its sightings among all steady fixes; the synthesis carries it as a gear until
// a model has it or it has not been sighted for kForgetTime. Readings at idle revs are no sightings:
// declutched, the car rolls at a slowly changing ratio. A gear sighted only at lugged revs (below those the
// driver holds any gear above first at) is marked a possible *creep*: a car crawling in a queue on a
// slipping clutch, the revs held just above the idle, shows a steady ratio that is no gear's.
//
// Fixed capacity, no allocation.
#include <array>
#include <span>

namespace gearpulse {

class SeenGears {
 public:
  static constexpr int kCapacity = 4;
  static constexpr double kForgetTime = 1800.0;  // s without a sighting before a gear is forgotten

  struct Gear {
    double theta = 0.0;      // (m/s)/Hz
    double std_error = 0.0;  // (m/s)/Hz
    double share = 0.0;      // its sightings' share of all steady fixes observed
    bool creep = false;      // sighted only at lugged revs: perhaps a clutch slipping at held revs
  };

  // min_fixes: sightings in a row before a gear counts as seen (not finite or <= 0: never).
  explicit SeenGears(double min_fixes = 0.0) noexcept : min_fixes_(min_fixes) {}

  // One fix (GPS speed, m/s) with the engine frequency at its time (Hz), at step time t (s). model_thetas:
  // the model's gears; idle_ceiling: revs at or below this are idle (Hz, 0 = unknown); lag: how late the
  // fix's speed is against the revs (s); lugged: the revs are ones this driver holds no gear above first
  // at. Returns true when the set of seen gears changed (one became seen or was forgotten, or a seen gear
  // was sighted at revs not lugged for the first time); a seen gear's theta may move without that.
  bool observe(double t, double speed, double freq, double idle_ceiling, std::span<const double> model_thetas,
               double lag, bool lugged = false) noexcept;
  // Forgets every gear within a gearbox step of one of `model_thetas` (a model that has learned it). Returns
  // true when the set of seen gears changed.
  bool forget_learned(std::span<const double> model_thetas) noexcept;
  // The seen gears, in no order; returns how many were written.
  int seen(std::array<Gear, kCapacity>& out) const noexcept;
  void clear() noexcept;

 private:
  struct Sighting {
    double count = 0.0;  // steady fixes sighted (0 = slot free)
    double mean = 0.0;   // their mean log ratio
    double m2 = 0.0;     // sum of squared departures from the mean
    double last_t = 0.0;
    double longest_run = 0.0;  // most steady fixes sighted in a row
    double above = 0.0;        // of them, at revs not lugged
  };
  [[nodiscard]] bool is_seen(const Sighting& s) const noexcept;

  double min_fixes_;
  std::array<Sighting, kCapacity> slots_{};
  bool have_prev_ = false;
  double prev_t_ = 0.0, prev_ratio_ = 0.0, prev_speed_ = 0.0;
  double steady_fixes_ = 0.0;  // steady fixes observed, on the model's lines or off them
  int run_slot_ = -1;          // the sighting the last fixes fell in, in a row (-1: none)
  double run_length_ = 0.0;    // how many
};

}  // namespace gearpulse
