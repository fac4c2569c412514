// One hop of the tracker: the track's filter over the window's evidence, the estimate and its confidence,
// and what the hop teaches (the fixed tones, the half order's presence, the 3rd harmonic's level).
#include "core/sliding_dft_tracker_impl.hpp"

#include <algorithm>
#include <cmath>

namespace gearpulse {

void SlidingDftTracker::Impl::reset_track() noexcept {
  track->reset();
  rho_track = kDefaultRho;
}

TrackPoint SlidingDftTracker::Impl::process_hop(std::uint64_t centre) noexcept {
  TrackPoint out;
  out.t = time_of(static_cast<double>(centre));
  if (centre < input.valid_from() + static_cast<std::uint64_t>(half_span) || !analyse(centre)) {
    reset_track();
    return out;
  }
  track->predict();
  tones->mark(track->predicted());
  floor_is_noise = rho_track < kLeakRho;
  candidate_likelihoods(track->evidence(), track->overrun_layers() ? &track->overrun_excess() : nullptr,
                        track->power_layers() ? &track->power_excess() : nullptr);
  const double level = std::min(1.0, kDefaultRho / rho_track);
  if (!track->update(kHiddenShare * level * level)) {
    reset_track();
    return out;
  }
  const int best = track->mode_bin();
  // The line's sub-bin position: near the track's prediction when that lies on the posterior's line (a
  // hop whose line is drowned must not jump to a noise peak within the lobe), else near the mode.
  const double predicted = track->predicted();
  const bool on_line = std::isfinite(predicted) && std::abs(predicted - best * df) <= lobe * df;
  const double f_mode = harmonic_peak_near(best, lobe) * df;
  Evidence ev = refine(f_mode, predicted);
  if (on_line) {
    const double f_pred = harmonic_peak_near(static_cast<int>(std::lround(predicted / df)), lobe / 2) * df;
    if (std::abs(f_pred - ev.freq) > df)
      if (Evidence alt = refine(f_pred, predicted); alt.log_likelihood > ev.log_likelihood) ev = alt;
  }
  ev.snr_db = snr_db(ev, true);
  out.snr_db = ev.snr_db;
  // Probability that the engine's fundamental is on the estimated line: within one resolution bin of the
  // estimate (the posterior of a line spreads over its main lobe, the refined estimate does not), or 5 %
  // where that is wider.
  const double right = track->mass_near(ev.freq);
  // A line sweeping through the window (mid gear-shift) smears its power over two resolution bins, and
  // the track may hold on to where the line was, on the smear's shoulder. A stronger fundamental peak
  // between one and two resolution bins away says so (sqrt z has unit-order noise, as for the shoulder
  // check of the candidates within one bin): the odds of this hop's estimate are weighed by that
  // mismatch. Only the report: the track's own state follows its posterior, so the next hops, whose
  // windows show where the line went, re-acquire it as before.
  double reported = right;
  if (const double m = sweep_mismatch(ev.freq); m > 0.0) {
    const double odds = right / std::max(1e-12, 1.0 - right) * std::exp(-m);
    reported = odds / (1.0 + odds);
  }
  const bool in_band = ev.freq >= cfg.band_lo_hz - df && ev.freq <= cfg.band_hi_hz + df;
  if (in_band) {
    out.freq = ev.freq;
    out.confidence = reported;
    out.tracked = reported >= kTrackedConfidence;
  }
  track->observe(ev.freq, right, reported >= kTrackedConfidence);
  // The track's fundamental level, for the matched test of the next hops.
  if (right >= kTrackedConfidence)
    rho_track = kRhoMemory * rho_track + (1.0 - kRhoMemory) * std::max(ev.snr[1] - 1.0, 1.0);
  else
    rho_track = kRhoMemory * rho_track + (1.0 - kRhoMemory) * kDefaultRho;
  learn_tones(ev.freq, right);
  // This signal's orders (the half order's presence, the 3rd harmonic's level), from hops that can tell: a
  // confident estimate with a loud fundamental or, before the track is confident, a harmonic pair.
  third_n *= third_keep;
  if (right >= kTrackedConfidence)
    learn_orders(ev, right);
  else
    learn_orders_from_pair();
  return out;
}

// The half order's presence and the 3rd harmonic's level, from a confident estimate with a loud fundamental.
void SlidingDftTracker::Impl::learn_orders(const Evidence& ev, double right) noexcept {
  // Written so that a NaN fails each test (a non-finite level would poison every later hop's prior).
  if (!(right >= kHalfObserveRight) || !(ev.snr[1] >= kHalfObserveRho) || !std::isfinite(ev.snr[1])) return;
  const double f1 = ev.freq / df;
  if (ev.available[0]) add_half(f1, ev.snr[0]);
  if (!ev.available[3] || !std::isfinite(ev.snr[3])) return;
  const auto k1 = static_cast<std::size_t>(std::clamp<long>(std::lround(f1), 0, nfft / 2));
  add_third_level(ev.snr[1] - 1.0, ev.snr[3], k1, static_cast<std::size_t>(std::lround(3.0 * f1)));
}

// A loud line with a line at exactly twice its frequency is a harmonic source's, whatever the track holds
// yet: the band's strongest such pair (within a fine bin, each kHalfObserveRho over the noise per bin,
// learned tones left out) teaches the half order's presence and the 3rd harmonic's level as a confident hop
// does. So a signal without those orders, whose absence would otherwise cost every state at the engine the
// fixed prior's kOrderAbsent twice at high SNR (more than its two lines' ratios, bounded by the tone prior,
// bring) and keep the track from ever being confident, learns that absence before it is tracked.
void SlidingDftTracker::Impl::learn_orders_from_pair() noexcept {
  int k = -1;
  double top = kHalfObserveRho, f1 = 0.0;
  for (int j = std::max(k_lo, 1); j <= k_hi; ++j) {
    const auto b = static_cast<std::size_t>(j);
    const double z = z_at(b);
    if (z < top || tones->near(b) || z < z_at(b - 1) || z < z_at(b + 1)) continue;
    const double f = peak_near(j, lobe / 2);
    if (3.0 * f * df > harmonic_limit_hz) continue;
    const double f2 = peak_near(static_cast<int>(std::lround(2.0 * f)), lobe / 2);
    const auto b2 = static_cast<std::size_t>(std::lround(f2));
    if (std::abs(f2 - 2.0 * f) > 1.0 || b2 >= tones->bins() || tones->near(b2) || z_at(b2) < kHalfObserveRho)
      continue;
    top = z;
    k = j;
    f1 = f;
  }
  if (k < 0) return;
  add_half(f1, z_at(static_cast<std::size_t>(std::lround(0.5 * f1))));
  const auto b3 = static_cast<std::size_t>(std::lround(3.0 * f1));
  add_third_level(top - 1.0, z_at(b3), static_cast<std::size_t>(k), b3);
}

// Adds one hop's half order: present when its bin (the fundamental's at fine bin f1, halved) stands out.
void SlidingDftTracker::Impl::add_half(double f1, double z_half) noexcept {
  const auto b = static_cast<std::size_t>(std::lround(0.5 * f1));
  if (b < tones->bins() && !tones->near(b))
    half_present = half_keep * half_present + (1.0 - half_keep) * (z_half >= kToneFitLevel ? 1.0 : 0.0);
}

// Adds one hop's 3rd harmonic level: the fundamental's per-bin SNR rho1 at fine bin k1, the normalised
// power z3 at the 3rd harmonic's bin b.
void SlidingDftTracker::Impl::add_third_level(double rho1, double z3, std::size_t k1,
                                              std::size_t b) noexcept {
  if (b >= tones->bins() || tones->near(b) || !std::isfinite(z3)) return;
  // A 3rd harmonic below the noise is read at the floor the fundamental's level lets show. The ratio is
  // of the lines' powers (each SNR times its bin's floor), as the orders' level priors.
  const double x = 10.0 * std::log10(std::max(z3 - 1.0, 1.0) / (rho1 * floor_ratio(k1, b)));
  third_n += 1.0;
  const double d = x - third_mean_db;
  third_mean_db += d / third_n;
  third_var_db = (1.0 - 1.0 / third_n) * (third_var_db + d * d / third_n);
}

// Learns the fixed tones from this window, leaving out the orders of the estimate `freq` while it is
// probably the engine (`right`, the probability that it is) and, while it is a candidate not yet
// confident, until they have persisted.
void SlidingDftTracker::Impl::learn_tones(double freq, double right) noexcept {
  const bool on_track = right >= 0.5;
  // A candidate: some belief in the estimate, a fundamental that holds its neighbourhood (the peak of its
  // line, not the shoulder of another: a fan read as a 2nd harmonic has no line of its own at the
  // estimate, and is learned at once) and another order standing out (a fan's tone has none).
  bool candidate = false;
  if (std::isfinite(freq) && right >= kToneCandidate) {
    const int kc = static_cast<int>(std::lround(freq / df));
    if (kc >= 1 && kc < nfft / 2) {
      const auto z = [this](int j) {
        return power()[static_cast<std::size_t>(j)] / noise()[static_cast<std::size_t>(j)];
      };
      const double own = z(kc);
      double peak = own;
      for (int j = std::max(1, kc - lobe); j <= std::min(nfft / 2 - 1, kc + lobe); ++j)
        peak = std::max(peak, z(j));
      const bool holds = own >= 0.5 * peak || std::sqrt(peak) - std::sqrt(own) <= kToneCandidateMismatch;
      bool ladder = false;
      for (int o = 0; o < kOrders && !ladder; ++o) {
        const double pos = kOrder[o] * freq / df;
        if (o == 1 || pos * df > harmonic_limit_hz || pos < noise_lo) continue;
        ladder = z(static_cast<int>(std::lround(pos))) >= kToneFitLevel;
      }
      // Only a line loud enough to become a tone within a few windows needs the grace: fainter ones are
      // learned over many, as before (a fan next to a faint engine line is learned as soon).
      candidate = holds && ladder && tones->loud(own);
    }
  }
  tones->learn(power().data(), noise().data(), freq, kOrder, on_track, candidate);
}

}  // namespace gearpulse
