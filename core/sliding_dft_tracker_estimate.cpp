// One window of the tracker: its spectrum, the sub-bin estimate of the fundamental (a joint least-squares
// fit of the engine's orders) and the estimate's SNR.
#include "core/sliding_dft_tracker_impl.hpp"

#include <fftw3.h>

#include <algorithm>
#include <cmath>
#include <complex>

namespace gearpulse {

// Decimates, detrends and tapers the window centred on input frame `centre`, then fills the power
// spectrum and the noise floor. False on a silent window.
bool SlidingDftTracker::Impl::analyse(std::uint64_t centre) noexcept {
  const std::uint64_t first = centre - static_cast<std::uint64_t>(half_span);
  const auto decim = static_cast<std::uint64_t>(input.factor());
  for (int j = 0; j < n_win; ++j) {
    const double acc = input.sample(first + static_cast<std::uint64_t>(j) * decim);
    dec[static_cast<std::size_t>(j)] = acc;
    raw[static_cast<std::size_t>(j)] = acc;
  }
  return spectrum->analyse(dec.data());
}

double SlidingDftTracker::Impl::noise_at(double fine_bin) const noexcept {
  const auto k = static_cast<std::size_t>(std::clamp<long>(std::lround(fine_bin), 0, nfft / 2));
  return noise()[k];
}

// Fine bin of the largest power within `reach` bins of k.
double SlidingDftTracker::Impl::peak_near(int k, int reach) const noexcept {
  int best = k;
  for (int i = std::max(1, k - reach); i <= std::min(nfft / 2 - 1, k + reach); ++i)
    if (power()[static_cast<std::size_t>(i)] > power()[static_cast<std::size_t>(best)]) best = i;
  if (best <= 0 || best >= nfft / 2) return best;
  // Gaussian interpolation: exact for the main lobe of a Gaussian window, close for Hann.
  const double a = std::log(std::max(power()[static_cast<std::size_t>(best - 1)], 1e-300));
  const double b = std::log(std::max(power()[static_cast<std::size_t>(best)], 1e-300));
  const double c = std::log(std::max(power()[static_cast<std::size_t>(best + 1)], 1e-300));
  const double den = a - 2.0 * b + c;
  double delta = den < 0.0 ? 0.5 * (a - c) / den : 0.0;
  delta = std::clamp(delta, -0.5, 0.5);
  return best + delta;
}

// Fine bin (fractional) of the largest harmonic sum (normalised power at f/2, f, 2f, 3f: the higher
// orders pin the fundamental more finely) within `reach` fine bins of k.
double SlidingDftTracker::Impl::harmonic_peak_near(int k, int reach) const noexcept {
  const auto sum_at = [this](int b) {
    double sum = 0.0;
    for (int o = 0; o < kOrders; ++o) {
      const double pos = kOrder[o] * b;
      if (pos * df > harmonic_limit_hz || pos < noise_lo) continue;
      const auto i = static_cast<std::size_t>(std::lround(pos));
      sum += z_at(i);
    }
    return sum;
  };
  int best = k;
  double best_sum = -1.0;
  for (int b = std::max(1, k - reach); b <= std::min(nfft / 2 - 1, k + reach); ++b)
    if (const double v = sum_at(b); v > best_sum) {
      best_sum = v;
      best = b;
    }
  if (best <= 1 || best >= nfft / 2 - 1) return best;
  const double a = sum_at(best - 1), c = sum_at(best + 1);
  const double den = a - 2.0 * best_sum + c;
  return best + (den < 0.0 ? std::clamp(0.5 * (a - c) / den, -0.5, 0.5) : 0.0);
}

// Energy of the window explained by a harmonic model at fundamental f: level, slope and a sinusoid at
// every order the decimated signal holds, fitted jointly by least squares (so the orders do not leak
// into each other as they would through a window). Its maximum over f is the ML estimate of f for a
// harmonic signal in white noise. Optionally returns the fitted fundamental's squared amplitude.
double SlidingDftTracker::Impl::harmonic_fit(double f, const bool* use, Fit* fit) const noexcept {
  double freq[kSlots];
  const double resolution = fd / n_win;
  for (int o = 0; o < kSlots; ++o) {
    freq[o] = kNaN;
    const double fo = slot_hz(o, f);
    if (o == kOrders) {
      // Two sinusoids closer than half a resolution bin cannot be told apart in one window.
      if (!std::isfinite(fo) || std::abs(fo - f) < 0.5 * resolution ||
          std::abs(fo - 2.0 * f) < 0.5 * resolution)
        continue;
    } else if (!use[o]) {
      continue;
    }
    if (fo > harmonic_limit_hz || fo / df < noise_lo) continue;
    freq[o] = fo;
  }
  return sines.fit(raw.data(), freq, fit);
}

// Noise variance per decimated sample inside the band: the fitted harmonic model is subtracted from the
// window, the rest tapered and transformed, and the median of its band bins (robust to lines the model
// does not hold, such as a fan) taken as an exponential variable's (median = mean x ln 2).
double SlidingDftTracker::Impl::residual_noise_level(double f, const Fit& fit) noexcept {
  const double sum_w2 = spectrum->taper_energy();
  if (fit.cols == 0) return noise_at(f / df) / sum_w2;
  double freq[kSlots];
  for (int o = 0; o < kSlots; ++o)
    freq[o] = fit.col[o] >= 0 ? slot_hz(o, f) : kNaN;
  sines.residual(raw.data(), freq, fit, spectrum->taper().data(), spectrum->residual());
  const fftw_complex* resid = spectrum->transform_residual();
  // The band's fine bins; the median by selection in the (now free) scratch of the noise floor.
  const int lo = std::max(noise_lo, k_lo), hi = std::max(lo, k_hi);
  double* scratch = spectrum->scratch();
  std::size_t n = 0;
  for (int k = lo; k <= hi; ++k) {
    // The fit notches the residual around every fitted frequency; those bins are not noise.
    bool notched = false;
    for (int o = 0; o < kSlots && !notched; ++o)
      notched = fit.col[o] >= 0 && std::abs(k * df - slot_hz(o, f)) <= lobe * df;
    if (notched) continue;
    const fftw_complex& v = resid[static_cast<std::size_t>(k)];
    scratch[n++] = v[0] * v[0] + v[1] * v[1];
  }
  if (n < 8) return noise_at(f / df) / sum_w2;
  std::nth_element(scratch, scratch + n / 2, scratch + n);
  // The fit removed `cols` of n_win degrees of freedom from the window.
  const double dof = static_cast<double>(n_win) / std::max(1, n_win - fit.cols);
  return scratch[n / 2] / std::log(2.0) / sum_w2 * dof;
}

// The band's noise level changes slowly: averaged geometrically over about a second (robust to one odd
// window) it no longer adds the scatter of one window's ~15 resolution bins to every SNR. The fitted
// power is corrected for the noise it holds (least squares over n samples: 2 sigma^2 / n).
double SlidingDftTracker::Impl::snr_db(const Evidence& ev, bool learn) noexcept {
  if (!(ev.noise_level > 0.0) || !std::isfinite(ev.noise_level)) return kNaN;
  const double now = std::log(ev.noise_level);
  const double smoothed =
      std::isfinite(log_noise) ? kNoiseMemory * log_noise + (1.0 - kNoiseMemory) * now : now;
  if (learn) log_noise = smoothed;
  const double sigma2 = std::exp(smoothed);
  const double noise_power = sigma2 * 2.0 * (cfg.band_hi_hz - cfg.band_lo_hz) / fd;
  const double signal_power = std::max(ev.fundamental_amp2 / 2.0 - 2.0 * sigma2 / n_win, 1e-3 * noise_power);
  return 10.0 * std::log10(signal_power / noise_power);
}

// Sub-bin estimate around f0 (Hz): grid then golden-section search of the harmonic least-squares fit
// (see harmonic_fit), then the evidence of every order at the refined frequency.
SlidingDftTracker::Impl::Evidence SlidingDftTracker::Impl::refine(double f0, double predicted) noexcept {
  Evidence ev;
  // The strongest learned tone within two resolution bins of the fundamental is fitted along.
  nuisance_hz = kNaN;
  {
    double strongest = kToneFitLevel;
    const auto c = static_cast<int>(std::lround(f0 / df));
    for (int k = std::max(noise_lo, c - 2 * lobe); k <= std::min(noise_hi, c + 2 * lobe); ++k)
      if (tones->learned(static_cast<std::size_t>(k)) &&
          tones->mean(static_cast<std::size_t>(k)) > strongest) {
        strongest = tones->mean(static_cast<std::size_t>(k));
        nuisance_hz = k * df;
      }
  }
  std::complex<double> x, dx, ddx;
  // An order whose neighbourhood is dominated by a line elsewhere (a fan next to the 2nd harmonic) would
  // pull the fit; leave it out. The fundamental always stays.
  const double bin = fd / n_win;  // resolution of the window, Hz
  bool use[kOrders];
  for (int o = 0; o < kOrders; ++o) {
    use[o] = true;
    if (o == 1) continue;
    const double centre = kOrder[o] * f0 / df;
    const int reach = static_cast<int>(std::ceil(1.5 * bin / df));
    // An order at or above the decimated signal's Nyquist frequency is not in the spectrum (a low input
    // rate): it cannot pull the fit, nor be looked up.
    if (centre + reach > nfft / 2 - 1) {
      use[o] = false;
      continue;
    }
    int best = static_cast<int>(std::lround(centre));
    for (int k = std::max(1, best - reach); k <= std::min(nfft / 2 - 1, best + reach); ++k)
      if (power()[static_cast<std::size_t>(k)] > power()[static_cast<std::size_t>(best)]) best = k;
    const bool strong = power()[static_cast<std::size_t>(best)] > 4.0 * noise_at(best);
    use[o] = !(strong && std::abs(best - centre) * df > 0.4 * bin);
  }
  // Log likelihood of f: the explained energy over twice the noise variance per sample, plus (on a
  // continuing track) a Gaussian prior around the track's prediction, which holds a hop whose line is
  // drowned in noise near where the engine must be instead of on a noise peak.
  const double inv_2s2 = spectrum->taper_energy() / (2.0 * noise_at(f0 / df));
  const bool with_prior = std::isfinite(predicted) && std::abs(predicted - f0) <= 2.5 * kPredictionHz;
  const auto objective = [&](double f) {
    const double dp = with_prior ? (f - predicted) / kPredictionHz : 0.0;
    return harmonic_fit(f, use, nullptr) * inv_2s2 - 0.5 * dp * dp;
  };
  // The coarse estimate is within a fraction of the window's resolution (1 / T); search +-0.3 / T.
  const double reach = 0.3 * fd / n_win;
  const double from = (with_prior ? std::min(f0, predicted) : f0) - reach;
  const double to = (with_prior ? std::max(f0, predicted) : f0) + reach;
  constexpr int kGrid = 8;
  const double step = (to - from) / kGrid;
  double best_f = f0, best_j = -INFINITY;
  for (int i = 0; i <= kGrid; ++i) {
    const double f = from + step * i;
    const double j = objective(f);
    if (j > best_j) {
      best_j = j;
      best_f = f;
    }
  }
  double a = best_f - step, b = best_f + step;
  constexpr double kGolden = 0.6180339887498949;
  double c = b - kGolden * (b - a), d = a + kGolden * (b - a);
  double jc = objective(c), jd = objective(d);
  for (int iter = 0; iter < 10; ++iter) {  // brackets the maximum to ~1 % of a grid step
    if (jc > jd) {
      b = d;
      d = c;
      jd = jc;
      c = b - kGolden * (b - a);
      jc = objective(c);
    } else {
      a = c;
      c = d;
      jc = jd;
      d = a + kGolden * (b - a);
      jd = objective(d);
    }
  }
  const double f = 0.5 * (a + b);
  ev.log_likelihood = objective(f);
  Fit fit;
  (void)harmonic_fit(f, use, &fit);
  ev.freq = f;
  int n_ladder = 0;
  double ladder = 0.0;
  for (int o = 0; o < kOrders; ++o) {
    const double fo = kOrder[o] * f;
    if (fo > harmonic_limit_hz || fo / df < noise_lo) continue;
    sines.dtft(dec.data(), 2.0 * kPi * fo / fd, x, dx, ddx);
    ev.available[o] = true;
    ev.snr[o] = std::norm(x) / noise_at(fo / df);
    if (o != 1) {
      ladder += ev.snr[o];
      ++n_ladder;
    }
  }
  ev.ladder_excess = ladder - n_ladder;
  // The window's noise level, from the residual of the harmonic fit (the engine's own lines and their
  // leakage removed), and the fitted fundamental's power, for the SNR (see snr_db()).
  ev.noise_level = residual_noise_level(f, fit);
  const int col = fit.col[1];
  ev.fundamental_amp2 =
      col >= 0 && fit.cols > 0 ? fit.coef[col] * fit.coef[col] + fit.coef[col + 1] * fit.coef[col + 1] : 0.0;
  ev.snr_db = snr_db(ev, false);
  return ev;
}

}  // namespace gearpulse
