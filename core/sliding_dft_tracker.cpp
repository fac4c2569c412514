#include "core/sliding_dft_tracker.hpp"

#include "core/decimating_input.hpp"
#include "core/sinusoid_fit.hpp"
#include "core/sliding_dft_tracker_evidence.hpp"
#include "core/tone_map.hpp"
#include "core/track_model.hpp"
#include "core/track_outputs.hpp"
#include "core/window_spectrum.hpp"

#include <fftw3.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <vector>

namespace gearpulse {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = std::numbers::pi;

// Orders of the engine component scored and refined: half-order, fundamental, 2nd and 3rd harmonic.
constexpr int kOrders = 4;
constexpr double kOrder[kOrders] = {0.5, 1.0, 2.0, 3.0};
// Per-bin SNR of the fundamental assumed before a track gives its level, and the memory of the track's
// level (per hop). 3 is a -5 dB line's level (against the noise of the 150 Hz default band) in one bin of a
// 0.1 s Hann window: 10^-0.5 x 150 x T / 1.5. At the default 0.16 s such a line gives 5.1, but scaling the
// assumed level with the window lets an unconfirmed line weigh more before it is followed (tuning scenes at
// 0.16 s, -5 dB: coverage 58.9 -> 57.6 %, gross 0.65 -> 2.07 %), so it stays at 3 whatever the window.
constexpr double kDefaultRho = 3.0;
constexpr double kRhoMemory = 0.7;
// A window hides the engine's line (a gear shift's smear, a line masked by another or faded below the
// evidence's level prior) with this probability when the line stands at the default level; a louder line
// is hidden less often, by the square of its per-bin SNR over the default (a loud line that vanishes has
// stopped or moved, and the track lets it go as fast as without the allowance). Otherwise a track at
// -5 dB passes to "engine absent" on the many windows where its line fades and restarts anywhere, often
// on twice the engine. Chosen on the generated scenes' tuning set (see docs/algorithms/tracker-method.md).
constexpr double kHiddenShare = 0.3;
// The candidates' shoulder term (a state on the shoulder of a stronger peak within one resolution bin is
// not where the line is) compares amplitudes (sqrt of normalised power) against unit-order noise and, on a
// loud line, against this share of its amplitude: a window's line is no stationary sinusoid centred on a
// fine bin (it sweeps, changes its level within the window and lies between bins), so the states place a
// line to about a quarter of a resolution bin (where a Hann main lobe is 4 % down in amplitude) and the
// sub-bin fit does the rest. Against noise alone the term grows with the line's level: a line 30-50 dB over
// the noise whose top a sweep has flattened loses several nats on every state, and the track passes to
// "engine absent" while the line stands clear.
constexpr double kShoulderShape = 0.05;
// Mean normalised power from which a learned tone is fitted along with the engine's orders.
constexpr double kToneFitLevel = ToneMap::kFitLevel;
constexpr double kToneCandidate = 0.05;  // probability from which the estimate's line is a candidate
// The estimate holds its line's peak when its power is within 3 dB of the peak's, or within the noise of it
// (sqrt of normalised power; the shoulder of a line one resolution bin away is 6 dB down).
constexpr double kToneCandidateMismatch = 2.0;
// Whether this signal carries a half order is learned from confident hops whose fundamental stands this
// far over the noise (per bin), so that a half order at the prior's lowest ratio (0.05) would show;
// over this time (s). Until then HarmonicEvidence::kOrderAbsent holds.
constexpr double kHalfObserveRho = 100.0;
constexpr double kHalfMemoryS = 1.0;
constexpr double kHalfObserveRight = 0.95;
// The 3rd harmonic's level against the fundamental is a property of the engine and its wiring (the shape of
// its firing pulse) and changes slowly: it is learned (dB, a mean and a spread over kThirdMemoryS) from the
// hops on which the half order's presence is learned (a confident estimate, a fundamental 20 dB over the
// noise per bin, so that a 3rd harmonic at -20 dB shows; a weaker one is read at that floor). The 3rd
// harmonic's level prior is then a mixture: the learned level (normal in dB, its spread widened by
// kThirdSpreadFloorDb) with weight n / (n + kThirdPriorS / hop) for n hops learned (exponentially
// forgotten), the fixed prior with the rest, so that the fixed prior is worth kThirdPriorS of such hops.
// The 2nd harmonic's level swings with load and the half order's presence is learned on its own (see
// docs/algorithms/tracker-method.md). Chosen on the generated scenes' tuning set.
constexpr double kThirdMemoryS = 10.0;
constexpr double kThirdPriorS = 0.5;
constexpr double kThirdSpreadFloorDb = 2.0;
// A bin's long-run level below the noise floor scales the floor down to its noise (ToneMap::background())
// while the track's line stands less than 30 dB over the noise per bin. A louder line leaks through the Hann
// window's sidelobes (31 dB down, falling 18 dB an octave) over much of a floor's block: the floor is then
// the leakage's, not a biased noise level, and scaled down there it lets a clean line's 2nd harmonic
// outweigh the line (docs/algorithms/tracker-method.md, "A floor read over the noise").
constexpr double kLeakRho = 1000.0;
// Memory (per hop) of the band's noise level behind the reported SNR.
constexpr double kNoiseMemory = 0.9;
// Uncertainty (Hz) of the track's prediction one hop ahead (about the slew of a ramping engine over a
// 0.1 s hop), the prior of the sub-bin estimate.
constexpr double kPredictionHz = 2.0;
// A hop is "tracked" when its estimate is right (within 5 % of the engine's fundamental) with probability
// 0.8 or more: the engine speed and the training pairs are built on it, so it must be right nearly every
// time; the probability itself is reported as the confidence.
constexpr double kTrackedConfidence = 0.8;
// at() keeps to the nearest hop output within this time.
constexpr double kCoastS = 0.5;
constexpr int kZeroPad = 8;

std::size_t next_pow2(std::size_t n) {
  std::size_t p = 1;
  while (p < n)
    p <<= 1;
  return p;
}

std::string format(const char* fmt, double a, double b = 0.0, double c = 0.0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}

}  // namespace

std::size_t extract_channel(std::span<const float> interleaved, int channels, int channel,
                            std::span<float> out) noexcept {
  if (channels <= 0 || channel >= channels) return 0;
  const std::size_t frames = std::min(out.size(), interleaved.size() / static_cast<std::size_t>(channels));
  const auto ch = static_cast<std::size_t>(channels);
  for (std::size_t i = 0; i < frames; ++i) {
    const float* f = interleaved.data() + i * ch;
    if (channel >= 0) {
      out[i] = f[channel];
    } else {
      double sum = 0.0;
      for (std::size_t c = 0; c < ch; ++c)
        sum += f[c];
      out[i] = static_cast<float>(sum / static_cast<double>(ch));
    }
  }
  return frames;
}

struct SlidingDftTracker::Impl {
  TrackerConfig cfg;
  double fs = 0.0;
  DecimatingInput input;           // the input frames and the decimator that reads windows from them
  double fd = 0.0;                 // decimated rate
  double harmonic_limit_hz = 0.0;  // highest frequency the decimated signal represents faithfully
  int n_win = 0;                   // decimated samples per window (odd)
  int nfft = 0;
  double df = 0.0;             // fine bin width (Hz)
  std::int64_t half_span = 0;  // input frames from a window centre to its first/last used frame
  std::int64_t hop_frames = 1;

  double t0 = 0.0;  // time of frame 0
  std::uint64_t next_centre = 0;

  // Per-hop scratch (sized at construction).
  std::vector<double> dec;                 // decimated window, detrended and tapered
  std::vector<double> raw;                 // decimated window as filtered (for the least-squares fit)
  std::optional<WindowSpectrum> spectrum;  // the window's power and noise floor per fine bin
  int k_lo = 0, k_hi = 0;                  // band, fine bins
  int s_lo = 0;                            // lowest state, fine bin (half the band's lower edge)
  int noise_lo = 1, noise_hi = 1;          // fine bins used for the noise floor
  const HarmonicEvidence& evidence = HarmonicEvidence::shared();
  double temper = 1.0;        // overlapping windows are not independent evidence
  double half_present = 1.0;  // share of clear confident hops that showed a half order (see kHalfMemoryS)
  double half_keep = 1.0;     // per hop
  // The 3rd harmonic's learned level ratio to the fundamental (see kThirdMemoryS): weight of the hops
  // learned, the ratio's mean and variance (dB).
  double third_n = 0.0, third_mean_db = 0.0, third_var_db = 0.0;
  double third_keep = 1.0;   // per hop
  double third_prior = 1.0;  // hops the fixed prior is worth
  int lobe = 1;              // fine bins per resolution bin (1 / window)

  // The track over hops: candidates are the fine bins s_lo..k_hi (from half the band's lower edge, so
  // that an idling engine is followed below the band and its 2nd harmonic is not taken for it).
  std::optional<TrackModel> track;
  std::vector<double> at_loglik;  // at()'s candidates, apart from the track's
  double rho_track = kDefaultRho;
  bool floor_is_noise = true;    // rho_track below kLeakRho (this hop)
  std::optional<ToneMap> tones;  // fixed tones of other equipment, counted as background

  TrackOutputs outputs;

  struct Evidence {
    double freq = kNaN;
    double snr[kOrders] = {0, 0, 0, 0};  // per-bin SNR (linear) at order x freq; 0 where unavailable
    bool available[kOrders] = {false, false, false, false};
    double ladder_excess = 0.0;
    double snr_db = kNaN;
    double log_likelihood = -INFINITY;  // of the refined frequency, with the track's prior if any
    double noise_level = kNaN;          // noise variance per decimated sample in the band, this window
    double fundamental_amp2 = 0.0;      // squared amplitude of the fitted fundamental
  };

  explicit Impl(const TrackerConfig& c);
  [[nodiscard]] const std::vector<double>& power() const noexcept { return spectrum->power(); }
  [[nodiscard]] const std::vector<double>& noise() const noexcept { return spectrum->noise(); }

  [[nodiscard]] double time_of(double frame) const noexcept { return t0 + frame / fs; }
  bool analyse(std::uint64_t centre) noexcept;
  [[nodiscard]] double noise_at(double fine_bin) const noexcept;
  // Normalised power of a fine bin, a learned fixed tone counted as background (only where it stands
  // clearly above the noise on average: a moving engine raises a bin's mean a little, not a lot), and a
  // floor read over the bin's noise scaled back to it while the floor is the noise's (floor_is_noise).
  [[nodiscard]] double z_at(std::size_t k) const noexcept {
    const double b = tones->background(k);
    return power()[k] / (noise()[k] * (b < 1.0 && !floor_is_noise ? 1.0 : b));
  }
  void learn_tones(double freq, double right) noexcept;
  // `overrun`, when given, gets what a line on the overrun adds to it (HarmonicEvidence::second_overrun()),
  // `power` what a line under power adds (HarmonicEvidence::second_power()).
  void candidate_likelihoods(std::vector<double>& out, std::vector<double>* overrun = nullptr,
                             std::vector<double>* power = nullptr) const noexcept;
  // Log odds lost by the state at fine bin k, whose line has per-bin SNR rho_line, to the root f / 4 of a
  // comb of which it would be the 4th harmonic.
  [[nodiscard]] double comb_root_penalty(int k, double rho_line) const noexcept;
  void learn_third(const Evidence& ev, double right) noexcept;
  void reset_track() noexcept;
  [[nodiscard]] double peak_near(int k, int reach) const noexcept;
  [[nodiscard]] double harmonic_peak_near(int k, int reach) const noexcept;
  [[nodiscard]] Evidence refine(double f0, double predicted = kNaN) noexcept;
  // Fundamental power over the band's noise power (the generator's definition), in dB. `learn`: the
  // window is the next hop's, whose noise level joins the average.
  [[nodiscard]] double snr_db(const Evidence& ev, bool learn) noexcept;
  // Least-squares model of a window: level, slope, a sinusoid per order and one for a learned fixed tone
  // next to the fundamental (slot kOrders), which would otherwise pull the fit.
  static constexpr int kSlots = kOrders + 1;
  static_assert(kSlots == SinusoidFit::kMaxSines);
  using Fit = SinusoidFit::Result;
  SinusoidFit sines{1, 1.0};
  double nuisance_hz = kNaN;  // the learned tone fitted along, for the current refine()
  double log_noise = kNaN;    // log of the band's noise variance per sample, averaged over hops
  [[nodiscard]] double slot_hz(int o, double f) const noexcept {
    return o < kOrders ? kOrder[o] * f : nuisance_hz;
  }
  [[nodiscard]] double harmonic_fit(double f, const bool* use, Fit* fit) const noexcept;
  [[nodiscard]] double sweep_mismatch(double f) const noexcept;
  [[nodiscard]] double residual_noise_level(double f, const Fit& fit) noexcept;
  TrackPoint process_hop(std::uint64_t centre) noexcept;
};

SlidingDftTracker::Impl::Impl(const TrackerConfig& c)
    : cfg(c),
      fs(c.sample_rate_hz),
      input(c.sample_rate_hz, 3.0 * c.band_hi_hz),  // up to the highest scored harmonic
      outputs(256, std::max<std::size_t>(
                       8, static_cast<std::size_t>(std::ceil(c.history_s / std::max(c.hop_s, 1e-3))) + 2)) {
  fd = input.rate_hz();
  harmonic_limit_hz = input.limit_hz();
  n_win = static_cast<int>(std::lround(cfg.window_s * fd));
  if (n_win % 2 == 0) ++n_win;
  nfft = static_cast<int>(next_pow2(static_cast<std::size_t>(kZeroPad * n_win)));
  sines = SinusoidFit(n_win, fd);
  df = fd / nfft;
  half_span = static_cast<std::int64_t>((n_win - 1) / 2) * input.factor() +
              static_cast<std::int64_t>(input.taps() / 2);
  hop_frames = std::max<std::int64_t>(1, std::llround(cfg.hop_s * fs));

  const auto history_frames = static_cast<std::size_t>(std::ceil(cfg.history_s * fs));
  input.reserve(history_frames + 2 * static_cast<std::size_t>(half_span) +
                static_cast<std::size_t>(hop_frames) + 16);

  dec.resize(static_cast<std::size_t>(n_win));
  raw.resize(static_cast<std::size_t>(n_win));
  const auto bins = static_cast<std::size_t>(nfft / 2 + 1);
  k_lo = static_cast<int>(std::ceil(cfg.band_lo_hz / df));
  k_hi = static_cast<int>(std::floor(cfg.band_hi_hz / df));
  noise_lo = std::max(1, static_cast<int>(std::floor(0.5 * cfg.band_lo_hz / df)));
  noise_hi = std::min(static_cast<int>(bins) - 2, static_cast<int>(std::ceil(harmonic_limit_hz / df)));
  s_lo = std::max(noise_lo, static_cast<int>(std::ceil(0.5 * cfg.band_lo_hz / df)));
  spectrum.emplace(n_win, nfft, noise_lo, noise_hi);
  const auto states = static_cast<std::size_t>(k_hi - s_lo + 1);
  at_loglik.assign(states, 0.0);
  temper = std::min(1.0, cfg.hop_s / cfg.window_s);
  half_keep = std::exp(-cfg.hop_s / kHalfMemoryS);
  third_keep = std::exp(-cfg.hop_s / kThirdMemoryS);
  third_prior = kThirdPriorS / cfg.hop_s;
  lobe = std::max(1, nfft / n_win);
  track.emplace(cfg, s_lo, k_hi, df, lobe);
  tones.emplace(bins, noise_lo, noise_hi, lobe, df, cfg.hop_s);
  reset_track();
}

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
      if (tones->mean(static_cast<std::size_t>(k)) > strongest) {
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

void SlidingDftTracker::Impl::reset_track() noexcept {
  track->reset();
  rho_track = kDefaultRho;
}

// A ladder at f is also what an engine at f / 4 shows when its ignition spikes give it every harmonic (a
// comb): f is then its 4th order, and an idle's 4th harmonic scores as well as the idle when the window
// is long enough for the comb's upper lines to reach the evidence's bound. The two roots predict the
// same lines at f's orders and differ at f / 4 and 3 f / 4: background under root f, the lower engine's
// fundamental and 3rd order under root f / 4. The log likelihood ratio S of those two bins (each an order
// of the lower engine, at -13 to +13 dB of f's line) gives, with the two roots equally likely beforehand,
// the posterior of root f; the state at f loses the log odds by which it is the less likely root,
// ln((1 + e^S) / 2) when S > 0, and nothing otherwise. Only the 4th order is judged so: f / 2 and 3 f / 2
// are a four-stroke's own half orders (the half order's level prior and the track's continuity tell f
// from f / 2), and f / 3 and 2 f / 3 lie a third of f apart, both inside a cabin's body resonance
// (20-40 Hz) for an engine at 60-120 Hz (see docs/algorithms/tracker-experiments.md).
double SlidingDftTracker::Impl::comb_root_penalty(int k, double rho_line) const noexcept {
  double s = 0.0;
  for (const int m : {1, 3}) {
    const double pos = 0.25 * m * k;
    const auto b = static_cast<std::size_t>(std::lround(pos));
    if (pos < noise_lo || tones->near(b)) return 0.0;  // unseen, or under a learned tone: says nothing
    s += evidence.lower_root(z_at(b), rho_line);
  }
  return s > 0.0 ? std::log(0.5 * (1.0 + std::exp(s))) : 0.0;
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
        const double fixed = o == 0   ? evidence.half_order(z, rho, half_absent)
                             : o == 2 ? evidence.second(z, rho, level)
                                      : evidence.order(z, rho, level);
        if (o == 2 && overrun) overrun_second = evidence.second_overrun(z, rho, level) - fixed;
        if (o == 2 && power) power_second = evidence.second_power(z, rho, level) - fixed;
        if (o != 3 || third_w <= 0.0) {
          l += fixed;
          continue;
        }
        // The mixture of the two priors, whose ratios to background add with the priors' weights.
        const double learned = evidence.profiled(z, rho * third_ratio, third_spread);
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

TrackPoint SlidingDftTracker::Impl::process_hop(std::uint64_t centre) noexcept {
  TrackPoint out;
  out.t = time_of(static_cast<double>(centre));
  if (centre < input.valid_from() + static_cast<std::uint64_t>(half_span) || !analyse(centre)) {
    reset_track();
    return out;
  }
  track->predict();
  tones->mark();
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
  // This signal's half order, from hops that can tell: a confident estimate with a loud fundamental.
  if (right >= kHalfObserveRight && ev.available[0] && ev.snr[1] >= kHalfObserveRho) {
    const auto b = static_cast<std::size_t>(std::lround(0.5 * ev.freq / df));
    if (b < tones->bins() && !tones->near(b))
      half_present = half_keep * half_present + (1.0 - half_keep) * (ev.snr[0] >= kToneFitLevel ? 1.0 : 0.0);
  }
  learn_third(ev, right);
  return out;
}

// The 3rd harmonic's level ratio, from hops that can tell: a confident estimate with a loud fundamental.
void SlidingDftTracker::Impl::learn_third(const Evidence& ev, double right) noexcept {
  third_n *= third_keep;
  // Written so that a NaN fails each test (a non-finite level would poison every later hop's prior).
  if (!(right >= kHalfObserveRight) || !ev.available[3] || !(ev.snr[1] >= kHalfObserveRho) ||
      !std::isfinite(ev.snr[1]) || !std::isfinite(ev.snr[3]))
    return;
  const double rho1 = ev.snr[1] - 1.0;
  const auto b = static_cast<std::size_t>(std::lround(3.0 * ev.freq / df));
  if (b >= tones->bins() || tones->near(b)) return;
  // A 3rd harmonic below the noise is read at the floor the fundamental's level lets show.
  const double x = 10.0 * std::log10(std::max(ev.snr[3] - 1.0, 1.0) / rho1);
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

// ---- public ----

std::string SlidingDftTracker::validate(const TrackerConfig& c) {
  const auto finite = [](double v) { return std::isfinite(v); };
  if (!finite(c.sample_rate_hz) || c.sample_rate_hz <= 0)
    return format("sample rate %g Hz is not a positive number", c.sample_rate_hz);
  if (!finite(c.band_lo_hz) || !finite(c.band_hi_hz) || c.band_lo_hz <= 0 || c.band_hi_hz <= c.band_lo_hz)
    return format("band %g:%g Hz is not a positive, increasing range", c.band_lo_hz, c.band_hi_hz);
  if (c.band_hi_hz >= 0.5 * c.sample_rate_hz)
    return format("band upper edge %g Hz is outside Nyquist (%g Hz at %g Hz sampling)", c.band_hi_hz,
                  0.5 * c.sample_rate_hz, c.sample_rate_hz);
  if (c.sample_rate_hz < 2.5 * c.band_hi_hz)
    return format("sample rate %g Hz is too low for a band up to %g Hz (needs at least %g Hz)",
                  c.sample_rate_hz, c.band_hi_hz, 2.5 * c.band_hi_hz);
  if (c.sample_rate_hz > 768000) return format("sample rate %g Hz is above 768000 Hz", c.sample_rate_hz);
  if (!finite(c.window_s) || c.window_s <= 0 || c.window_s > 2.0)
    return format("window %g s is outside (0, 2] s", c.window_s);
  if (c.window_s * c.band_lo_hz < 4.0)
    return format("window %g s is too short for the band: it must hold 4 periods of %g Hz (%g s)", c.window_s,
                  c.band_lo_hz, 4.0 / c.band_lo_hz);
  if (!finite(c.hop_s) || c.hop_s <= 0 || c.hop_s > 60.0)
    return format("hop %g s is outside (0, 60] s", c.hop_s);
  if (c.hop_s * c.sample_rate_hz < 1.0)
    return format("hop %g s is shorter than one frame at %g Hz", c.hop_s, c.sample_rate_hz);
  if (c.hop_s > 4.0 * c.window_s)
    return format("hop %g s is more than 4 windows (%g s): the audio between windows would be ignored",
                  c.hop_s, 4.0 * c.window_s);
  // No engine's frequency changes by more than some hundreds of Hz per second; the bound keeps the gates
  // (in bins) far from integer overflow.
  constexpr double kMaxSlew = 1e5;  // Hz/s
  if (!finite(c.max_slew_hz_per_s) || c.max_slew_hz_per_s < 0 || c.max_slew_hz_per_s > kMaxSlew)
    return format("max slew %g Hz/s is outside [0, %g] Hz/s", c.max_slew_hz_per_s, kMaxSlew);
  if (!finite(c.shift_slew_hz_per_s) || c.shift_slew_hz_per_s < 0 || c.shift_slew_hz_per_s > kMaxSlew)
    return format("shift slew %g Hz/s is outside [0, %g] Hz/s", c.shift_slew_hz_per_s, kMaxSlew);
  if (!finite(c.history_s) || c.history_s < 0 || c.history_s > 60)
    return format("history %g s is outside [0, 60] s", c.history_s);
  return {};
}

std::unique_ptr<SlidingDftTracker> SlidingDftTracker::create(const TrackerConfig& config,
                                                             std::string& error) {
  error = validate(config);
  if (!error.empty()) return nullptr;
  try {
    return std::make_unique<SlidingDftTracker>(config);
  } catch (const std::exception& e) {
    error = e.what();
    return nullptr;
  }
}

SlidingDftTracker::SlidingDftTracker(const TrackerConfig& config) {
  if (std::string error = validate(config); !error.empty()) throw std::invalid_argument(error);
  impl_ = std::make_unique<Impl>(config);
  start(0.0);
}

SlidingDftTracker::~SlidingDftTracker() = default;

void SlidingDftTracker::start(double t0) noexcept {
  Impl& s = *impl_;
  s.t0 = t0;
  s.input.clear();
  const auto first_hop = (s.half_span + s.hop_frames - 1) / s.hop_frames;
  s.next_centre = static_cast<std::uint64_t>(first_hop * s.hop_frames);
  s.reset_track();
  s.tones->reset();
  s.half_present = 1.0;  // the half order is the source's: learned again from the new stream
  s.third_n = s.third_mean_db = s.third_var_db = 0.0;  // so is the 3rd harmonic's level
  s.log_noise = kNaN;
  s.outputs.clear();
}

void SlidingDftTracker::retime(double t_next) noexcept {
  impl_->t0 = t_next - static_cast<double>(impl_->input.received()) / impl_->fs;
}

void SlidingDftTracker::skip(std::uint64_t frames) noexcept {
  Impl& s = *impl_;
  if (frames == 0) return;
  s.input.skip(frames);
  s.reset_track();
  // Hops whose windows overlap the hole give no output; resume on the hop grid after it.
  const auto h = static_cast<std::uint64_t>(s.hop_frames);
  const std::uint64_t min_centre = s.input.valid_from() + static_cast<std::uint64_t>(s.half_span);
  if (s.next_centre < min_centre) s.next_centre = (min_centre + h - 1) / h * h;
}

void SlidingDftTracker::push(std::span<const float> frames) noexcept {
  Impl& s = *impl_;
  std::size_t i = 0;
  while (i < frames.size()) {
    const std::uint64_t needed = s.next_centre + static_cast<std::uint64_t>(s.half_span) + 1;
    while (i < frames.size() && s.input.received() < needed)
      s.input.write(frames[i++]);
    if (s.input.received() >= needed) {
      s.outputs.emit(s.process_hop(s.next_centre));
      s.next_centre += static_cast<std::uint64_t>(s.hop_frames);
    }
  }
}

bool SlidingDftTracker::pop(TrackPoint& out) noexcept {
  Impl& s = *impl_;
  return s.outputs.pop(out);
}

TrackPoint SlidingDftTracker::at(double t) noexcept {
  Impl& s = *impl_;
  TrackPoint out;
  out.t = t;
  const double pos = (t - s.t0) * s.fs;
  if (!std::isfinite(pos)) return out;
  const double c = std::round(pos);
  const auto hs = static_cast<double>(s.half_span);
  const auto received = static_cast<double>(s.input.received());
  const double oldest = std::max(static_cast<double>(s.input.valid_from()),
                                 received - static_cast<double>(s.input.capacity()) + 1.0);
  if (c - hs < oldest || c + hs >= received) return out;
  const auto centre = static_cast<std::uint64_t>(c);
  out.t = s.time_of(c);
  // Prior: the nearest hop output with an estimate, within the coast time; this window's estimate is
  // the best candidate within the slew gate around it, and inherits its confidence.
  TrackPoint prior;
  double prior_dt = 1e9;
  for (std::size_t k = 0; k < s.outputs.held(); ++k) {
    const TrackPoint& h = s.outputs.recent(k);
    if (std::isfinite(h.freq) && std::abs(h.t - out.t) < prior_dt) {
      prior_dt = std::abs(h.t - out.t);
      prior = h;
    }
  }
  if (!std::isfinite(prior.freq) || prior_dt > kCoastS || !s.analyse(centre)) return out;
  const double gate = s.cfg.max_slew_hz_per_s * prior_dt + 2.0 * s.df + 1.0;
  const int lo = std::max(s.s_lo, static_cast<int>(std::floor((prior.freq - gate) / s.df)));
  const int hi = std::min(s.k_hi, static_cast<int>(std::ceil((prior.freq + gate) / s.df)));
  if (lo > hi) return out;
  s.candidate_likelihoods(s.at_loglik);  // the track state stays as the hops left it
  int best = lo;
  for (int k = lo; k <= hi; ++k)
    if (s.at_loglik[static_cast<std::size_t>(k - s.s_lo)] >
        s.at_loglik[static_cast<std::size_t>(best - s.s_lo)])
      best = k;
  const Impl::Evidence ev = s.refine(s.harmonic_peak_near(best, s.lobe) * s.df);
  out.snr_db = ev.snr_db;
  if (std::abs(ev.freq - prior.freq) <= gate && ev.freq >= s.cfg.band_lo_hz - s.df &&
      ev.freq <= s.cfg.band_hi_hz + s.df) {
    out.freq = ev.freq;
    out.confidence = prior.confidence;
    out.tracked = prior.tracked;
  }
  return out;
}

TrackPoint SlidingDftTracker::nearest(double t) const noexcept {
  const Impl& s = *impl_;
  TrackPoint best;
  best.t = t;
  double best_dt = 0.5 * s.cfg.hop_s + 1e-9;
  for (std::size_t k = 0; k < s.outputs.held(); ++k) {
    const TrackPoint& h = s.outputs.recent(k);
    if (std::abs(h.t - t) <= best_dt) {
      best_dt = std::abs(h.t - t);
      best = h;
    }
  }
  return best;
}

double SlidingDftTracker::latest_time() const noexcept {
  const Impl& s = *impl_;
  const auto last = static_cast<std::int64_t>(s.input.received()) - 1 - s.half_span;
  if (last < static_cast<std::int64_t>(s.input.valid_from()) + s.half_span) return kNaN;
  return s.time_of(static_cast<double>(last));
}

const TrackerConfig& SlidingDftTracker::config() const noexcept {
  return impl_->cfg;
}
double SlidingDftTracker::decimated_rate_hz() const noexcept {
  return impl_->fd;
}
std::size_t SlidingDftTracker::queue_capacity() const noexcept {
  return impl_->outputs.queue_capacity();
}
std::size_t SlidingDftTracker::max_push_frames() const noexcept {
  return std::max<std::size_t>(
      1, impl_->outputs.queue_capacity() / 2 * static_cast<std::size_t>(impl_->hop_frames));
}
std::size_t SlidingDftTracker::history_size() const noexcept {
  return impl_->outputs.history_capacity();
}
std::uint64_t SlidingDftTracker::dropped_outputs() const noexcept {
  return impl_->outputs.dropped();
}

}  // namespace gearpulse
