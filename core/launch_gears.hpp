#pragma once
// How many gears a launch from rest passes below the lowest gear the synthesis has measured (its *base*:
// the lowest gear of its ladder that is not predicted). A young model lacks the launch gears, which are
// never steady under GPS, and where the base carries the car at idle no faster than a first gear may, the
// idle cannot tell whether the base is first. A launch can: GPS shows the car standing, then moving; the
// engine frequency, read at every step, falls by a gearbox step at each upshift; and once the filter holds
// the base, or a gear above it, confidently under GPS, the upshifts counted since the car stood, less the
// gears of the ladder from the base up to that one, are the gears the launch drove below the base. A car
// whose base is first reaches it with no upshift (the clutch slips at held revs, then bites in first), one
// that lacks first gear after one upshift, and so on.
//
// Each launch so counted is a reading of the gears below the base, off by one at times (a launch in
// second gear, a shift missed or a fall of the revs that was none): with `off_share` the share of such
// readings, the count k has a posterior under which a reading equal to k has likelihood 1 - off_share and
// any other off_share / kMaxBelow; its prior is off_share^j for j gears more or fewer than the idle
// requires (each as unlikely as a reading that is off: the idle's bound is a car's, and a motorcycle's
// high idle or a tall first gear carries it faster), so one launch against none decides, and readings
// that disagree weigh against each other. The counts belong to one base: a new one starts them afresh.
//
// Fixed capacity, no allocation.
#include <array>

namespace gearpulse {

class LaunchGears {
 public:
  static constexpr int kMaxBelow = 4;  // the most gears counted below the base
  // s: a launch's first gear is held about this long (the geometric mean of 412 stints in first gear ended
  // by second, under GPS on the simulated drives; synthesis-experiments.md, "At sparse readings"): revs
  // read further apart than that pass first gear unread, and their launches are not counted.
  static constexpr double kFirstGearHeld = 1.5;
  // Idle spreads above the idle at or below which the engine idles (the revs a launch starts from).
  static constexpr double kIdleSds = 3.0;

  // At every step with GPS present: the engine frequency (NaN if not tracked), the base's step to the gear
  // above it (log theta ratio; 0 at the top of the ladder), and the revs at or below which the engine is
  // at idle (Hz; 0 = unknown).
  void observe_revs(double freq, double step, double idle_ceiling) noexcept;
  // At every new fix, at step time t (s): whether GPS shows the car standing, the base's theta, and the gear
  // the filter holds confidently, as ladder positions above the base (0: the base itself; -1: none, a gear
  // below the base, a move-off or a declutch). A launch held first in a gear `above` positions over the base
  // passed the ones between by as many upshifts, which are not gears below it.
  void observe_fix(double t, bool standing, double base_theta, int above) noexcept;
  // The launches a fit counted in its log on a base of `base_theta` (extra.launch_gears), per count k of
  // upshifts: where they show more gears below that base than the idle requires, the prior of the count
  // is centred there (gears_below).
  void seed(double base_theta, const std::array<double, kMaxBelow + 1>& counts) noexcept;
  // GPS was lost, the steps paused, the ladder went or the filter restarted: a launch in progress is not
  // counted.
  void abort() noexcept { state_ = State::kIdle; }

  // The most probable count of gears below a base of `base_theta`, the prior centred on `idle_count` (the
  // gears the idle requires below it): idle_count when no launch was counted on that base.
  [[nodiscard]] int gears_below(double base_theta, int idle_count, double off_share) const noexcept;
  // Launches counted on the current base with k upshifts before it (k = kMaxBelow: that many or more; 0
  // for any k outside 0..kMaxBelow).
  [[nodiscard]] double launches(int k) const noexcept {
    return k >= 0 && k <= kMaxBelow ? counts_[static_cast<std::size_t>(k)] : 0.0;
  }

 private:
  [[nodiscard]] bool same_base(double base_theta) const noexcept;

  enum class State { kIdle, kStanding, kLaunch };
  State state_ = State::kIdle;
  int upshifts_ = 0;         // counted since the car stood
  bool falling_ = false;     // the revs are falling through an upshift counted
  double peak_ = 0.0;        // highest log revs since the car stood or the last upshift ended
  double trough_ = 0.0;      // lowest log revs of the upshift in progress
  double moved_ = 0.0;       // time of the first fix moving
  double base_theta_ = 0.0;  // the base the counts belong to (0: none)
  std::array<double, kMaxBelow + 1> counts_{};
  double fit_base_ = 0.0;  // the base the fit's counts belong to (0: none)
  std::array<double, kMaxBelow + 1> fit_counts_{};
};

}  // namespace gearpulse
