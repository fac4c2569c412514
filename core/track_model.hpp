#pragma once
// The engine-frequency tracker's model of the track over hops: a hidden Markov chain over candidate
// fundamentals (fine spectral bins) and the line's rate of change (layers of rates within the slew), plus
// an "engine absent" state, filtered forward with each hop's evidence, and the track's continuity (the
// drift of a confident line and the latest tracked estimate).
//
// Per hop: predict() spreads the previous posterior (a continuing line moves at its rate within a steady
// gate, or its rate changes within a slew or a shift gate, which for a rising line reaches only below it;
// the engine stops, starts or is found elsewhere; a line found again after the track lost it is found near
// the latest tracked estimate or where an upshift from it leads), the caller writes
// every fundamental's log likelihood ratio into evidence() (and, for the falling rates of engine braking,
// overrun_excess(), for the fast rising rates under power, power_excess()), update() applies it to every rate
// (allowing for a window that hides the line), and observe() tells the model what the hop reported. Sized at
// construction; nothing allocates, locks or throws afterwards.
#include <vector>

#include "core/sliding_dft_tracker.hpp"

namespace gearpulse {

class TrackModel {
 public:
  // States: fine bins first_bin..last_bin of width df_hz (Hz), lobe fine bins to a resolution bin.
  TrackModel(const TrackerConfig& config, int first_bin, int last_bin, double df_hz, int lobe);

  void reset() noexcept;
  void predict() noexcept;
  // Per fundamental (first_bin + i): this hop's log likelihood ratio, written by the caller before update().
  // Windows that overlap (a hop shorter than the window) are not independent evidence: a hop's ratio is
  // the window's raised to hop / window (the temper).
  [[nodiscard]] std::vector<double>& evidence() noexcept { return loglik_; }
  // For a line on the overrun, whose orders' levels differ (engine braking: the 2nd harmonic often stands
  // over the fundamental), what its log likelihood ratio adds to evidence()'s, per fundamental: read by the
  // rate layers falling at kOverrunHzPerS or faster (when overrun_layers()). Zero, the same evidence,
  // unless the caller writes it; it keeps what was written.
  [[nodiscard]] std::vector<double>& overrun_excess() noexcept { return overrun_excess_; }
  [[nodiscard]] bool overrun_layers() const noexcept { return overrun_layers_ > 0; }
  // A line falling at this rate (Hz/s) or faster is on the overrun: revs fall that fast (600 rpm/s on a
  // four-cylinder) only while the engine does not drive the car (engine braking, or the clutch in and the
  // revs falling to idle). Chosen on the generated scenes' tuning set (10, 20 and 30 Hz/s; see
  // docs/algorithms/tracker-method.md).
  static constexpr double kOverrunHzPerS = 20.0;
  // For a line under power, whose 2nd harmonic seldom stands over the fundamental, what its log likelihood
  // ratio adds to evidence()'s, per fundamental: read by the rate layers rising at kPowerHzPerS or faster
  // (when power_layers()). Zero unless the caller writes it; it keeps what was written.
  [[nodiscard]] std::vector<double>& power_excess() noexcept { return power_excess_; }
  [[nodiscard]] bool power_layers() const noexcept { return power_from_ < layers_; }
  // A line rising at this rate (Hz/s) or faster is under power: revs rise 900 rpm/s on a four-cylinder
  // only at a wide throttle in the low gears. Chosen on the generated scenes' tuning set (20 and 30 Hz/s;
  // see docs/algorithms/tracker-method.md).
  static constexpr double kPowerHzPerS = 30.0;
  // Bayes update with evidence(), when the window hides the engine's line with probability `hidden` (a
  // gear shift's smear, a line masked by another or faded below the evidence's level prior): a hidden
  // window says nothing about where the engine is, so each state's likelihood ratio is the mixture
  // (1 - hidden) e^E + hidden for the window's E (tempered as the evidence is). One window then takes at
  // most ln(1 / hidden) from a line the track has followed. False (the model reset) when the posterior
  // is degenerate.
  // Where an upshift from the latest tracked estimate leads (the restart's range below), on every hop while
  // there is such an estimate, the layers that read the usual evidence take the better of it and the
  // overrun's: aimed at the new gear's first windows, which follow a shift with the throttle closed, at
  // light load, where the 2nd harmonic may stand over the fundamental (a limit of 0.5-2 s after the
  // shift measured the same, so there is none).
  bool update(double hidden) noexcept;

  [[nodiscard]] int mode_bin() const noexcept;
  // Posterior probability that the engine's fundamental is within 5 % (or one resolution bin) of f.
  [[nodiscard]] double mass_near(double f) const noexcept;
  // Where the line continues this hop (the previous confident estimate plus its drift), NaN when the
  // previous hop was not confident.
  [[nodiscard]] double predicted() const noexcept;
  // The hop's estimate f, the posterior near it (`right`) and whether it was reported as tracked.
  void observe(double f, double right, bool tracked) noexcept;

  [[nodiscard]] int first_bin() const noexcept { return first_; }
  [[nodiscard]] int last_bin() const noexcept { return last_; }

 private:
  double hop_s_, max_slew_;
  double temper_ = 1.0;  // hop / window, at most 1
  int first_, last_;
  double df_;
  int lobe_;
  int gate_steady_ = 1, gate_slew_ = 1, gate_shift_ = 1;      // fine bins per hop
  double keep_ = 1.0, slew_share_ = 0.0, shift_share_ = 0.0;  // per hop
  double p_stop_ = 0.0, p_start_ = 0.0, p_jump_ = 0.0;        // per hop
  // Rate layers: the posterior over (fundamental, rate of change); layer j moves rate_bins_[j] fine bins
  // per hop. post_ holds the layers one after another, marginal_ their sum per fundamental.
  int layers_ = 1;
  std::vector<double> rate_bins_;
  std::vector<double> post_, next_, marginal_, loglik_, cumsum_, moved_;
  // The rising layers (rise_from_ .. layers_ - 1, a positive rate) summed per fundamental, and its prefix
  // sums: their shift gate reaches below the line only (an upshift).
  int rise_from_ = 1;
  std::vector<double> rising_, rising_cumsum_;
  // update(): each fundamental's likelihood factor, common to every layer that is neither on the overrun
  // nor under power, the overrun's (layers 0 .. overrun_layers_ - 1, the fastest falling) and power's.
  std::vector<double> factor_, factor_overrun_, factor_power_;
  // The fundamentals where an upshift from the latest tracked estimate leads (up_lo_ .. up_hi_, none when
  // up_hi_ < up_lo_), set by predict(), and what the layers that read the usual evidence take there: the
  // better of the usual and the overrun's ratio (a new gear's first windows at light load).
  int up_lo_ = 0, up_hi_ = -1;
  std::vector<double> factor_upshift_;
  std::vector<double> overrun_excess_, power_excess_;
  int overrun_layers_ = 0;
  int power_from_ = 1;  // the layers rising at kPowerHzPerS or faster: power_from_ .. layers_ - 1
  double post_absent_ = 0.5;
  double drift_hz_per_s_ = 0.0;  // recent rate of change of the tracked line
  double last_freq_ = 0.0;       // previous hop's estimate while confident, else NaN
  double anchor_freq_ = 0.0;     // latest tracked estimate, NaN after a reset
  int anchor_age_ = 0;           // hops since it
};

}  // namespace gearpulse
