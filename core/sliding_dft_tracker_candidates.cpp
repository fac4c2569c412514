// The evidence of one window for every candidate fundamental (a state of the track): the log likelihood
// ratio of its harmonic ladder, and the checks on a line's shoulder and on a comb's root.
#include "core/sliding_dft_tracker_impl.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <iterator>
#include <vector>

namespace gearpulse {

// A ladder at f is also what an engine at f / r shows when its ignition spikes give it every harmonic (a
// comb): f is then its r-th order, and the comb's lines at f's orders score as well as a line of its own
// when the window is long enough for the comb's upper lines to reach the evidence's bound (at high SNR the
// 2nd and 3rd multiples do). Three roots are judged, r = 4, 2 and 3, each by bins where the lower engine
// has lines that are neither f's orders nor a four-stroke's low half orders (f / 2 and 3 f / 2, whose level
// prior tells f from f / 2), nor both inside a cabin's body resonance (20-40 Hz) for an engine at 60-120 Hz
// (as f / 3 and 2 f / 3 are): f / 4 and 3 f / 4 (the lower engine's 1st and 3rd orders), 5 f / 2 and 7 f / 2
// (its 5th and 7th), 4 f / 3 and 5 f / 3 (its 4th and 5th). The 3rd root is judged at 8 f / 3 too (its 8th),
// between f's 2nd and 3rd orders: those two read the comb's 6th and 9th, above the band where the floor is
// the noise's and the comb stands over it, while 4 f / 3 and 5 f / 3 may lie in the band, whose crowd of
// lines holds the floor over the comb; 8 f / 3 is also a line when f is 1.5 times a four-stroke engine at
// 2 f / 3 (that engine's 4th harmonic), which 7 f / 3 (its 3.5 order) is not. Under root f those bins hold
// background, under root f / r the lower engine's orders, each at -15 to +30 dB of f's line; S_r is their log
// likelihood ratio. With root f and the n roots judged equally likely beforehand, the posterior of root f is
// 1 / (1 + sum e^S_r); the state at f loses the log odds by which that falls short of its prior,
// ln((1 + sum e^S_r) / (1 + n)) when positive (ln((1 + e^S) / 2) with one root, the 4th's test alone). The
// posterior rather than the largest root's penalty: a root whose bins show background (S_r < 0) takes its
// share of the prior and says f is not its multiple, which the largest would ignore, and the tests'
// overlap (an engine at f / 4 has lines at 5 f / 2 and 7 f / 2 too, its 10th and 14th orders) counts one
// comb at most twice, ln 2 of the penalty. A bin below the noise floor's range, or under a learned tone,
// voids its root's test (says nothing); one above the harmonic limit is left out, and a root left without a
// bin says nothing (see docs/algorithms/tracker-experiments.md).
double SlidingDftTracker::Impl::comb_root_penalty(int k, double rho_line) const noexcept {
  using Root = std::array<double, 3>;  // the lower engine's orders tested, as multiples of f (0: none)
  static constexpr std::array<Root, 3> kRoots{
      {{0.25, 0.75, 0.0}, {2.5, 3.5, 0.0}, {4.0 / 3.0, 5.0 / 3.0, 8.0 / 3.0}}};
  std::array<double, kRoots.size()> log_odds{};  // each judged root's over root f
  std::size_t judged = 0;
  for (const Root& root : kRoots) {
    double s = 0.0;
    int counted = 0;
    bool void_test = false;
    for (const double m : root) {
      if (m == 0.0) break;
      const double pos = m * k;
      if (pos * df > harmonic_limit_hz) continue;
      const auto b = static_cast<std::size_t>(std::lround(pos));
      if (pos < noise_lo || tones->near(b)) {  // unseen, or under a learned tone: says nothing
        void_test = true;
        break;
      }
      s += evidence.lower_root(z_at(b), rho_line);
      ++counted;
    }
    if (!void_test && counted > 0) log_odds[judged++] = s;
  }
  if (judged == 0) return 0.0;
  // ln(1 + sum e^S_r), kept finite for a loud comb.
  const auto judged_end = log_odds.begin() + static_cast<std::ptrdiff_t>(judged);
  const double top = std::max(0.0, *std::max_element(log_odds.begin(), judged_end));
  double sum = std::exp(-top);
  for (std::size_t r = 0; r < judged; ++r)
    sum += std::exp(log_odds[r] - top);
  return std::max(0.0, top + std::log(sum) - std::log(1.0 + static_cast<double>(judged)));
}

// Log likelihood ratio of every state (engine line at that fine bin over noise-or-tone), from the
// normalised power at each of its orders.
void SlidingDftTracker::Impl::candidate_likelihoods(std::vector<double>& out, std::vector<double>* overrun,
                                                    std::vector<double>* power) const noexcept {
  const double half_absent = 1.0 - (1.0 - HarmonicEvidence::kOrderAbsent) * half_present;
  // The 3rd harmonic's learned level: its weight in the prior, its mean (a ratio) and spread (dB).
  const double third_w = third_n / (third_n + third_prior);
  const double third_ratio = std::pow(10.0, 0.1 * third_mean_db);
  const double third_spread = std::sqrt(third_var_db + kThirdSpreadFloorDb * kThirdSpreadFloorDb);
  for (int k = s_lo; k <= k_hi; ++k) {
    const double z1 = z_at(static_cast<std::size_t>(k));
    // A line puts its maximum where it is: a state on the shoulder of a stronger peak within one
    // resolution bin is penalised by the amplitude mismatch (sqrt z has unit-order noise).
    double peak = z1;
    for (int j = std::max(0, k - lobe); j <= std::min(nfft / 2, k + lobe); ++j)
      if (!tones->near(static_cast<std::size_t>(j))) peak = std::max(peak, z_at(static_cast<std::size_t>(j)));
    // On a loud line the mismatch is counted against the line's shape error (kShoulderShape of its
    // amplitude) as well as the noise.
    const double mismatch =
        (std::sqrt(peak) - std::sqrt(z1)) / std::sqrt(1.0 + kShoulderShape * kShoulderShape * peak);
    // A bin within a resolution bin of a learned tone says nothing either way: the engine may or may
    // not be under the tone or its shoulders.
    const bool on_tone = tones->near(static_cast<std::size_t>(k));
    double l = on_tone ? 0.0 : evidence.fundamental(z1, rho_track) - mismatch * mismatch;
    double overrun_second = 0.0;  // the overrun's 2nd harmonic term less the usual one
    double power_second = 0.0;    // the same under power
    if (cfg.require_harmonics) {
      // The fundamental's level that scales the other orders: the track's under a learned tone, else read
      // from this bin, whose scatter the orders' terms average over (HarmonicEvidence::Level).
      const double rho = on_tone ? rho_track : std::max(z1 - 1.0, 0.1);
      const auto level = on_tone ? HarmonicEvidence::Level::kTrack : HarmonicEvidence::Level::kRead;
      for (int o = 0; o < kOrders; ++o) {
        if (o == 1) continue;
        const double pos = kOrder[o] * k;
        if (pos * df > harmonic_limit_hz || pos < noise_lo) continue;
        const auto b = static_cast<std::size_t>(std::lround(pos));
        if (tones->near(b)) continue;
        const double z = z_at(b);
        // The orders' level priors are ratios of the lines' powers: a level read from this bin is carried
        // to the order's bin through the two floors (a crowded band's floor stands over the noise, the
        // floor above it does not). The track's level, read over earlier windows, stays a per-bin SNR.
        const double rho_o = on_tone ? rho : rho * floor_ratio(static_cast<std::size_t>(k), b);
        const double fixed = o == 0   ? evidence.half_order(z, rho_o, half_absent)
                             : o == 2 ? evidence.second(z, rho_o, level)
                                      : evidence.order(z, rho_o, level);
        if (o == 2 && overrun) overrun_second = evidence.second_overrun(z, rho_o, level) - fixed;
        if (o == 2 && power) power_second = evidence.second_power(z, rho_o, level) - fixed;
        if (o != 3 || third_w <= 0.0) {
          l += fixed;
          continue;
        }
        // The mixture of the two priors, whose ratios to background add with the priors' weights.
        const double learned = evidence.profiled(z, rho_o * third_ratio, third_spread);
        const double m = std::max(fixed, learned);
        l += m + std::log((1.0 - third_w) * std::exp(fixed - m) + third_w * std::exp(learned - m));
      }
      // The line's level (its peak's, not the state's on its shoulder) sets the lower root's expected level.
      const double lo = l + overrun_second;
      const double lp = l + power_second;
      const double penalty = l > 0.0 || (overrun && lo > 0.0) || (power && lp > 0.0)
                                 ? comb_root_penalty(k, on_tone ? rho_track : std::max(peak - 1.0, 0.1))
                                 : 0.0;
      const double usual = l > 0.0 ? l - penalty : l;
      if (overrun)
        (*overrun)[static_cast<std::size_t>(k - s_lo)] = temper * ((lo > 0.0 ? lo - penalty : lo) - usual);
      if (power)
        (*power)[static_cast<std::size_t>(k - s_lo)] = temper * ((lp > 0.0 ? lp - penalty : lp) - usual);
      l = usual;
    }
    out[static_cast<std::size_t>(k - s_lo)] = temper * l;
  }
}

// Squared mismatch (sqrt of normalised power) between the strongest fundamental peak one to two
// resolution bins from f (learned tones left out) and the power at f; 0 when f holds its neighbourhood.
double SlidingDftTracker::Impl::sweep_mismatch(double f) const noexcept {
  const int kc = static_cast<int>(std::lround(f / df));
  if (kc < s_lo || kc > nfft / 2 - 1) return 0.0;
  const double z_est = z_at(static_cast<std::size_t>(kc));
  double z_peak = z_est;
  for (int k = std::max(s_lo, kc - 2 * lobe); k <= std::min(nfft / 2 - 1, kc + 2 * lobe); ++k)
    if (std::abs(k - kc) > lobe && !tones->near(static_cast<std::size_t>(k)))
      z_peak = std::max(z_peak, z_at(static_cast<std::size_t>(k)));
  const double m = std::sqrt(z_peak) - std::sqrt(z_est);
  return m * m;
}

}  // namespace gearpulse
