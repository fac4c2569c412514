#include "core/sliding_dft_tracker.hpp"

#include <fftw3.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <mutex>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace gearpulse {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = std::numbers::pi;

// Orders of the engine component scored and refined: half-order, fundamental, 2nd and 3rd harmonic.
constexpr int kOrders = 4;
constexpr double kOrder[kOrders] = {0.5, 1.0, 2.0, 3.0};
// Weight of each order in the candidate score: the fundamental dominates so that the sub-octave (whose
// "2nd harmonic" is our fundamental) and the octave (whose "half order" is our fundamental) lose.
constexpr double kScoreWeight[kOrders] = {0.5, 1.0, 0.7, 0.5};
// Per-bin SNR above which one line cannot add to a candidate's score: a loud fixed tone without a
// ladder must not outweigh a quieter line with harmonics.
constexpr double kScoreCap = 30.0;
// Forward dynamic program: memory of past evidence and the cost of jumping beyond the slew gate.
constexpr double kMemory = 0.7;
constexpr double kJumpPenalty = 2.0;
// Detection thresholds on the per-bin SNR of the fundamental (noise-only bins are Exp(1) distributed):
// acquisition must beat the maximum of ~20 noise bins, keeping a line already followed need not.
constexpr double kAcquireSnr = 5.0;  // on the mean SNR of a run of consistent estimates
constexpr double kKeepSnr = 3.0;     // accumulated
constexpr double kKeepSnrNow = 2.2;  // this hop alone
// Ladder evidence: summed per-bin SNR of the other orders minus its noise-only expectation, averaged
// exponentially along a run of consistent estimates (noise-only: mean 0, standard deviation ~0.7).
constexpr double kAcquireLadder = 2.5;
constexpr double kReacquireLadder = 1.0;  // for a run that inherited an engine's evidence
constexpr double kKeepLadder = 0.0;
constexpr double kLadderMemory = 0.7;
// A line lost for longer than this is re-acquired, not kept.
constexpr double kCoastS = 0.5;
// Engine evidence younger than this carries over (scaled) to a new line: shifts and leaving idle.
constexpr double kCarryS = 1.0;
constexpr double kCarry = 0.8;
constexpr double kIdleExitHz = 25.0;
// Anti-alias filter: decimated rate at least this multiple of the highest scored harmonic.
constexpr double kDecimationMargin = 2.4;
constexpr double kStopbandDb = 70.0;
constexpr int kZeroPad = 8;
constexpr int kNoiseBlock = 192;  // fine bins per noise-floor block

struct FftwFree {
  void operator()(void* p) const noexcept { fftw_free(p); }
};

// The FFTW planner is not thread-safe; trackers may be built on several threads.
std::mutex& planner_mutex() {
  static std::mutex m;
  return m;
}

double bessel_i0(double x) {
  double sum = 1.0, term = 1.0;
  for (int k = 1; k < 50; ++k) {
    term *= (x / (2.0 * k)) * (x / (2.0 * k));
    sum += term;
    if (term < 1e-17 * sum) break;
  }
  return sum;
}

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
  int decim = 1;
  double fd = 0.0;                 // decimated rate
  double harmonic_limit_hz = 0.0;  // highest frequency the decimated signal represents faithfully
  std::vector<double> fir;         // odd length, linear phase, unit DC gain
  int n_win = 0;                   // decimated samples per window (odd)
  int nfft = 0;
  double df = 0.0;             // fine bin width (Hz)
  std::vector<double> window;  // Hann
  double sum_w = 0.0, sum_w2 = 0.0;
  std::int64_t half_span = 0;  // input frames from a window centre to its first/last used frame
  std::int64_t hop_frames = 1;

  // Input ring, written twice (i and i + size) so any span up to `ring_size` frames is contiguous.
  std::size_t ring_size = 0;
  std::vector<float> ring;
  std::uint64_t n_in = 0;        // frames received (including skipped ones)
  std::uint64_t valid_from = 0;  // first frame after the latest hole
  double t0 = 0.0;               // time of frame 0
  std::uint64_t next_centre = 0;

  // Per-hop scratch (sized at construction).
  std::vector<double> dec;  // decimated window, detrended and tapered
  std::vector<double> raw;  // decimated window as filtered (for the least-squares fit)
  std::unique_ptr<double, FftwFree> fft_in;
  std::unique_ptr<fftw_complex, FftwFree> fft_out;
  fftw_plan plan = nullptr;
  std::vector<double> power;
  std::vector<double> noise;  // per fine bin
  std::vector<double> block_scratch;
  int k_lo = 0, k_hi = 0;          // candidate fine bins (band)
  int noise_lo = 1, noise_hi = 1;  // fine bins used for the noise floor
  std::vector<double> alpha, alpha_next;
  bool alpha_valid = false;

  // Track state.
  bool tracking = false;
  double last_freq = kNaN;
  double last_tracked_t = kNaN;
  double ladder_acc = 0.0;
  double snr_acc = 0.0;
  double half_acc = 0.0;
  double cand_freq = kNaN;  // latest estimate, tracked or not
  double cand_t = kNaN;
  int cand_hops = 0;
  bool carried = false;    // the current run inherited an engine's evidence
  double engine_t = kNaN;  // last time a line with an engine's ladder was seen (tracked or at idle)
  double engine_ladder = 0.0;
  double engine_freq = kNaN;

  // Largest plausible change of the engine frequency over dt seconds.
  [[nodiscard]] double slew_gate(double dt) const noexcept {
    return cfg.max_slew_hz_per_s * dt + 2.0 * df + 1.0;
  }
  // Largest change at a gear shift, followed only while the line stays strong.
  [[nodiscard]] double shift_gate(double dt) const noexcept {
    return std::max(cfg.max_slew_hz_per_s, cfg.shift_slew_hz_per_s) * dt + 2.0 * df + 1.0;
  }

  // Output queue and hop history (fixed rings).
  std::vector<TrackPoint> queue;
  std::size_t q_head = 0, q_size = 0;
  std::vector<TrackPoint> history;
  std::size_t h_head = 0, h_size = 0;
  std::uint64_t dropped = 0;

  struct Evidence {
    double freq = kNaN;
    double snr[kOrders] = {0, 0, 0, 0};  // per-bin SNR (linear) at order x freq; 0 where unavailable
    bool available[kOrders] = {false, false, false, false};
    double ladder_excess = 0.0;
    double snr_db = kNaN;
  };

  explicit Impl(const TrackerConfig& c);
  ~Impl();

  [[nodiscard]] double time_of(double frame) const noexcept { return t0 + frame / fs; }
  void write_frame(float x) noexcept {
    if (!std::isfinite(x)) x = 0.0f;  // a glitch must not poison every window that sees it
    const std::size_t i = static_cast<std::size_t>(n_in) & (ring_size - 1);
    ring[i] = x;
    ring[i + ring_size] = x;
    ++n_in;
  }
  bool analyse(std::uint64_t centre) noexcept;
  [[nodiscard]] double noise_at(double fine_bin) const noexcept;
  [[nodiscard]] double power_near(double fine_bin, int tol) const noexcept;
  void score_candidates(std::vector<double>& score) const noexcept;
  [[nodiscard]] double peak_near(int k, int reach) const noexcept;
  [[nodiscard]] Evidence refine(double f0) const noexcept;
  void dtft(double omega, std::complex<double>& x, std::complex<double>& dx,
            std::complex<double>& ddx) const noexcept;
  [[nodiscard]] double harmonic_fit(double f, const bool* use, double* fundamental_amp2) const noexcept;
  TrackPoint process_hop(std::uint64_t centre) noexcept;
  void emit(const TrackPoint& p) noexcept;
};

SlidingDftTracker::Impl::Impl(const TrackerConfig& c) : cfg(c), fs(c.sample_rate_hz) {
  const double top = 3.0 * cfg.band_hi_hz;  // highest scored harmonic
  decim = std::max(1, static_cast<int>(std::floor(fs / (kDecimationMargin * top))));
  fd = fs / decim;
  if (decim > 1) {
    // Kaiser-windowed sinc: passband up to `top`, stopband from fd - top (what would alias below top).
    const double transition = fd - 2.0 * top;
    const double beta = 0.1102 * (kStopbandDb - 8.7);
    int len = static_cast<int>(std::ceil((kStopbandDb - 8.0) / (2.285 * 2.0 * kPi * transition / fs))) + 1;
    if (len % 2 == 0) ++len;
    const double fc = 0.5 * fd / fs;  // cycles per input sample
    fir.resize(static_cast<std::size_t>(len));
    const int mid = len / 2;
    double sum = 0.0;
    for (int i = 0; i < len; ++i) {
      const double m = i - mid;
      const double sinc = m == 0 ? 2.0 * fc : std::sin(2.0 * kPi * fc * m) / (kPi * m);
      const double r = m / mid;
      const double kaiser = bessel_i0(beta * std::sqrt(std::max(0.0, 1.0 - r * r))) / bessel_i0(beta);
      fir[static_cast<std::size_t>(i)] = sinc * kaiser;
      sum += fir[static_cast<std::size_t>(i)];
    }
    for (double& h : fir)
      h /= sum;
    harmonic_limit_hz = top;
  } else {
    fir.assign(1, 1.0);
    harmonic_limit_hz = 0.45 * fs;
  }

  n_win = static_cast<int>(std::lround(cfg.window_s * fd));
  if (n_win % 2 == 0) ++n_win;
  nfft = static_cast<int>(next_pow2(static_cast<std::size_t>(kZeroPad * n_win)));
  df = fd / nfft;
  window.resize(static_cast<std::size_t>(n_win));
  for (int i = 0; i < n_win; ++i) {
    const double w = 0.5 - 0.5 * std::cos(2.0 * kPi * (i + 1) / (n_win + 1));
    window[static_cast<std::size_t>(i)] = w;
    sum_w += w;
    sum_w2 += w * w;
  }
  half_span = static_cast<std::int64_t>((n_win - 1) / 2) * decim + static_cast<std::int64_t>(fir.size() / 2);
  hop_frames = std::max<std::int64_t>(1, std::llround(cfg.hop_s * fs));

  const auto history_frames = static_cast<std::size_t>(std::ceil(cfg.history_s * fs));
  ring_size = next_pow2(history_frames + 2 * static_cast<std::size_t>(half_span) +
                        static_cast<std::size_t>(hop_frames) + 16);
  ring.assign(2 * ring_size, 0.0f);

  dec.resize(static_cast<std::size_t>(n_win));
  raw.resize(static_cast<std::size_t>(n_win));
  const auto bins = static_cast<std::size_t>(nfft / 2 + 1);
  fft_in.reset(static_cast<double*>(fftw_malloc(sizeof(double) * static_cast<std::size_t>(nfft))));
  fft_out.reset(static_cast<fftw_complex*>(fftw_malloc(sizeof(fftw_complex) * bins)));
  if (!fft_in || !fft_out) throw std::bad_alloc();
  {
    const std::lock_guard lock(planner_mutex());
    plan = fftw_plan_dft_r2c_1d(nfft, fft_in.get(), fft_out.get(), FFTW_ESTIMATE);
  }
  if (!plan) throw std::runtime_error("SlidingDftTracker: FFTW could not make a plan");
  std::fill(fft_in.get(), fft_in.get() + nfft, 0.0);
  power.assign(bins, 0.0);
  noise.assign(bins, 0.0);
  block_scratch.assign(bins, 0.0);

  k_lo = static_cast<int>(std::ceil(cfg.band_lo_hz / df));
  k_hi = static_cast<int>(std::floor(cfg.band_hi_hz / df));
  noise_lo = std::max(1, static_cast<int>(std::floor(0.5 * cfg.band_lo_hz / df)));
  noise_hi = std::min(static_cast<int>(bins) - 2, static_cast<int>(std::ceil(harmonic_limit_hz / df)));
  alpha.assign(static_cast<std::size_t>(k_hi - k_lo + 1), 0.0);
  alpha_next.assign(alpha.size(), 0.0);

  queue.resize(256);
  history.resize(std::max<std::size_t>(
      8, static_cast<std::size_t>(std::ceil(cfg.history_s / std::max(cfg.hop_s, 1e-3))) + 2));
}

SlidingDftTracker::Impl::~Impl() {
  if (plan) {
    const std::lock_guard lock(planner_mutex());
    fftw_destroy_plan(plan);
  }
}

// Decimates, detrends and tapers the window centred on input frame `centre`, then fills the power
// spectrum and the noise floor. False on a silent window.
bool SlidingDftTracker::Impl::analyse(std::uint64_t centre) noexcept {
  const int mid = (n_win - 1) / 2;
  const std::size_t taps = fir.size();
  const std::uint64_t first = centre - static_cast<std::uint64_t>(half_span);
  for (int j = 0; j < n_win; ++j) {
    const std::uint64_t start = first + static_cast<std::uint64_t>(j) * static_cast<std::uint64_t>(decim);
    const float* x = ring.data() + (static_cast<std::size_t>(start) & (ring_size - 1));
    double acc = 0.0;
    for (std::size_t k = 0; k < taps; ++k)
      acc += fir[k] * static_cast<double>(x[k]);
    dec[static_cast<std::size_t>(j)] = acc;
    raw[static_cast<std::size_t>(j)] = acc;
  }
  // Least-squares line removal: the supply level and its slow drift are not the ripple.
  double s0 = 0.0, s1 = 0.0, s2 = 0.0;
  for (int j = 0; j < n_win; ++j) {
    const double m = j - mid;
    s0 += dec[static_cast<std::size_t>(j)];
    s1 += m * dec[static_cast<std::size_t>(j)];
    s2 += m * m;
  }
  const double mean = s0 / n_win;
  const double slope = s2 > 0 ? s1 / s2 : 0.0;
  double energy = 0.0, level = 0.0;
  for (int j = 0; j < n_win; ++j) {
    const auto i = static_cast<std::size_t>(j);
    level = std::max(level, std::abs(dec[i]));
    const double v = (dec[i] - mean - slope * (j - mid)) * window[i];
    dec[i] = v;
    fft_in.get()[i] = v;
    energy += v * v;
  }
  if (!(energy > 1e-20 * std::max(1.0, level * level * n_win)) || !std::isfinite(energy)) return false;
  fftw_execute_dft_r2c(plan, fft_in.get(), fft_out.get());
  const int bins = nfft / 2 + 1;
  for (int k = 0; k < bins; ++k) {
    const auto i = static_cast<std::size_t>(k);
    power[i] = fft_out.get()[i][0] * fft_out.get()[i][0] + fft_out.get()[i][1] * fft_out.get()[i][1];
  }
  // Noise floor: lower quartile per block of fine bins (robust to the lines of the engine and of other
  // equipment), as the mean of an exponential variable (q25 / ln(4/3)), interpolated linearly between block
  // centres (coloured noise).
  const int span = noise_hi - noise_lo + 1;
  const int blocks = std::max(1, span / kNoiseBlock);
  const double block_len = static_cast<double>(span) / blocks;
  double prev_centre = 0.0, prev_level = 0.0;
  for (int b = 0; b < blocks; ++b) {
    const int lo = noise_lo + static_cast<int>(std::lround(b * block_len));
    const int hi = noise_lo + static_cast<int>(std::lround((b + 1) * block_len));
    const auto n = static_cast<std::size_t>(hi - lo);
    std::copy(power.begin() + lo, power.begin() + hi, block_scratch.begin());
    std::nth_element(block_scratch.begin(), block_scratch.begin() + static_cast<std::ptrdiff_t>(n / 4),
                     block_scratch.begin() + static_cast<std::ptrdiff_t>(n));
    const double level_b = std::max(block_scratch[n / 4] / std::log(4.0 / 3.0), 1e-300);
    const double centre_b = 0.5 * (lo + hi);
    if (b == 0) {
      for (int k = 0; k <= static_cast<int>(centre_b); ++k)
        noise[static_cast<std::size_t>(k)] = level_b;
    } else {
      for (int k = static_cast<int>(prev_centre) + 1; k <= static_cast<int>(centre_b); ++k) {
        const double a = (k - prev_centre) / (centre_b - prev_centre);
        noise[static_cast<std::size_t>(k)] = prev_level + a * (level_b - prev_level);
      }
    }
    prev_centre = centre_b;
    prev_level = level_b;
  }
  for (int k = static_cast<int>(prev_centre) + 1; k < bins; ++k)
    noise[static_cast<std::size_t>(k)] = prev_level;
  return true;
}

double SlidingDftTracker::Impl::noise_at(double fine_bin) const noexcept {
  const auto k = static_cast<std::size_t>(std::clamp<long>(std::lround(fine_bin), 0, nfft / 2));
  return noise[k];
}

double SlidingDftTracker::Impl::power_near(double fine_bin, int tol) const noexcept {
  const long c = std::lround(fine_bin);
  double best = 0.0;
  for (long k = std::max<long>(0, c - tol); k <= std::min<long>(nfft / 2, c + tol); ++k)
    best = std::max(best, power[static_cast<std::size_t>(k)]);
  return best;
}

void SlidingDftTracker::Impl::score_candidates(std::vector<double>& score) const noexcept {
  for (int k = k_lo; k <= k_hi; ++k) {
    double s = 0.0;
    for (int o = 0; o < kOrders; ++o) {
      const double pos = kOrder[o] * k;
      if (pos * df > harmonic_limit_hz || pos < noise_lo) {
        s += kScoreWeight[o] * std::log1p(1.0);  // neutral: what noise would give
        continue;
      }
      const double snr = power_near(pos, kOrder[o] >= 2.0 ? 1 : 0) / noise_at(pos);
      s += kScoreWeight[o] * std::log1p(std::min(snr, kScoreCap));
    }
    score[static_cast<std::size_t>(k - k_lo)] = s;
  }
}

// Fine bin of the largest power within `reach` bins of k.
double SlidingDftTracker::Impl::peak_near(int k, int reach) const noexcept {
  int best = k;
  for (int i = std::max(1, k - reach); i <= std::min(nfft / 2 - 1, k + reach); ++i)
    if (power[static_cast<std::size_t>(i)] > power[static_cast<std::size_t>(best)]) best = i;
  if (best <= 0 || best >= nfft / 2) return best;
  // Gaussian interpolation: exact for the main lobe of a Gaussian window, close for Hann.
  const double a = std::log(std::max(power[static_cast<std::size_t>(best - 1)], 1e-300));
  const double b = std::log(std::max(power[static_cast<std::size_t>(best)], 1e-300));
  const double c = std::log(std::max(power[static_cast<std::size_t>(best + 1)], 1e-300));
  const double den = a - 2.0 * b + c;
  double delta = den < 0.0 ? 0.5 * (a - c) / den : 0.0;
  delta = std::clamp(delta, -0.5, 0.5);
  return best + delta;
}

// DTFT of the tapered window and its first two derivatives in omega (radians per decimated sample),
// with the time origin at the window centre.
void SlidingDftTracker::Impl::dtft(double omega, std::complex<double>& x, std::complex<double>& dx,
                                   std::complex<double>& ddx) const noexcept {
  const int mid = (n_win - 1) / 2;
  const std::complex<double> step = std::polar(1.0, -omega);
  std::complex<double> e = std::polar(1.0, omega * mid);  // e^{-j omega m} at m = -mid
  x = dx = ddx = 0.0;
  for (int j = 0; j < n_win; ++j) {
    const double m = j - mid;
    const std::complex<double> v = dec[static_cast<std::size_t>(j)] * e;
    x += v;
    dx += std::complex<double>(0.0, -m) * v;
    ddx += -m * m * v;
    e *= step;
  }
}

// Energy of the window explained by a harmonic model at fundamental f: level, slope and a sinusoid at
// every order the decimated signal holds, fitted jointly by least squares (so the orders do not leak
// into each other as they would through a window). Its maximum over f is the ML estimate of f for a
// harmonic signal in white noise. Optionally returns the fitted fundamental's squared amplitude.
double SlidingDftTracker::Impl::harmonic_fit(double f, const bool* use,
                                             double* fundamental_amp2) const noexcept {
  constexpr int kMaxCols = 2 + 2 * kOrders;
  double gram[kMaxCols][kMaxCols] = {};
  double rhs[kMaxCols] = {};
  std::complex<double> rot[kOrders], phasor[kOrders];
  int order_col[kOrders];
  int cols = 2;
  const int mid = (n_win - 1) / 2;
  for (int o = 0; o < kOrders; ++o) {
    order_col[o] = -1;
    const double fo = kOrder[o] * f;
    if (!use[o] || fo > harmonic_limit_hz || fo / df < noise_lo) continue;
    order_col[o] = cols;
    cols += 2;
    const double w = 2.0 * kPi * fo / fd;
    rot[o] = std::polar(1.0, w);
    phasor[o] = std::polar(1.0, -w * mid);
  }
  double v[kMaxCols];
  for (int j = 0; j < n_win; ++j) {
    v[0] = 1.0;
    v[1] = static_cast<double>(j - mid) / std::max(1, mid);
    for (int o = 0; o < kOrders; ++o) {
      if (order_col[o] < 0) continue;
      v[order_col[o]] = phasor[o].real();
      v[order_col[o] + 1] = phasor[o].imag();
      phasor[o] *= rot[o];
    }
    const double y = raw[static_cast<std::size_t>(j)];
    for (int a = 0; a < cols; ++a) {
      rhs[a] += v[a] * y;
      for (int b = 0; b <= a; ++b)
        gram[a][b] += v[a] * v[b];
    }
  }
  // Cholesky solve (lower triangle); a degenerate model explains nothing.
  double l[kMaxCols][kMaxCols] = {};
  for (int a = 0; a < cols; ++a) {
    for (int b = 0; b <= a; ++b) {
      double sum = gram[a][b];
      for (int k = 0; k < b; ++k)
        sum -= l[a][k] * l[b][k];
      if (a == b) {
        if (!(sum > 1e-9 * gram[a][a])) return 0.0;
        l[a][a] = std::sqrt(sum);
      } else {
        l[a][b] = sum / l[b][b];
      }
    }
  }
  double z[kMaxCols], x[kMaxCols];
  for (int a = 0; a < cols; ++a) {
    double sum = rhs[a];
    for (int k = 0; k < a; ++k)
      sum -= l[a][k] * z[k];
    z[a] = sum / l[a][a];
  }
  double explained = 0.0;
  for (int a = 0; a < cols; ++a)
    explained += z[a] * z[a];
  if (fundamental_amp2) {
    for (int a = cols - 1; a >= 0; --a) {
      double sum = z[a];
      for (int k = a + 1; k < cols; ++k)
        sum -= l[k][a] * x[k];
      x[a] = sum / l[a][a];
    }
    const int c = order_col[1];
    *fundamental_amp2 = c >= 0 ? x[c] * x[c] + x[c + 1] * x[c + 1] : 0.0;
  }
  return explained;
}

// Sub-bin estimate around f0 (Hz): grid then golden-section search of the harmonic least-squares fit
// (see harmonic_fit), then the evidence of every order at the refined frequency.
SlidingDftTracker::Impl::Evidence SlidingDftTracker::Impl::refine(double f0) const noexcept {
  Evidence ev;
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
    int best = static_cast<int>(std::lround(centre));
    for (int k = std::max(1, best - reach); k <= std::min(nfft / 2 - 1, best + reach); ++k)
      if (power[static_cast<std::size_t>(k)] > power[static_cast<std::size_t>(best)]) best = k;
    const bool strong = power[static_cast<std::size_t>(best)] > 4.0 * noise_at(best);
    use[o] = !(strong && std::abs(best - centre) * df > 0.4 * bin);
  }
  // The coarse estimate is within a fraction of the window's resolution (1 / T); search +-0.3 / T.
  const double reach = 0.3 * fd / n_win;
  constexpr int kGrid = 6;
  double best_f = f0, best_j = -1.0;
  for (int i = 0; i <= kGrid; ++i) {
    const double f = f0 - reach + 2.0 * reach * i / kGrid;
    const double j = harmonic_fit(f, use, nullptr);
    if (j > best_j) {
      best_j = j;
      best_f = f;
    }
  }
  double a = best_f - 2.0 * reach / kGrid, b = best_f + 2.0 * reach / kGrid;
  constexpr double kGolden = 0.6180339887498949;
  double c = b - kGolden * (b - a), d = a + kGolden * (b - a);
  double jc = harmonic_fit(c, use, nullptr), jd = harmonic_fit(d, use, nullptr);
  for (int iter = 0; iter < 14; ++iter) {
    if (jc > jd) {
      b = d;
      d = c;
      jd = jc;
      c = b - kGolden * (b - a);
      jc = harmonic_fit(c, use, nullptr);
    } else {
      a = c;
      c = d;
      jc = jd;
      d = a + kGolden * (b - a);
      jd = harmonic_fit(d, use, nullptr);
    }
  }
  const double f = 0.5 * (a + b);
  double amp2 = 0.0;
  (void)harmonic_fit(f, use, &amp2);
  ev.freq = f;
  int n_ladder = 0;
  double ladder = 0.0;
  for (int o = 0; o < kOrders; ++o) {
    const double fo = kOrder[o] * f;
    if (fo > harmonic_limit_hz || fo / df < noise_lo) continue;
    dtft(2.0 * kPi * fo / fd, x, dx, ddx);
    ev.available[o] = true;
    ev.snr[o] = std::norm(x) / noise_at(fo / df);
    if (o != 1) {
      ladder += ev.snr[o];
      ++n_ladder;
    }
  }
  ev.ladder_excess = ladder - n_ladder;
  // Fundamental power over in-band noise power, in the generator's definition: amplitude from the
  // fit, noise variance from the per-bin floor of the tapered spectrum.
  const double signal_power = std::max(amp2 / 2.0, 1e-300);
  const double noise_power = noise_at(f / df) / sum_w2 * 2.0 * (cfg.band_hi_hz - cfg.band_lo_hz) / fd;
  ev.snr_db = 10.0 * std::log10(signal_power / noise_power);
  return ev;
}

TrackPoint SlidingDftTracker::Impl::process_hop(std::uint64_t centre) noexcept {
  TrackPoint out;
  out.t = time_of(static_cast<double>(centre));
  if (centre < valid_from + static_cast<std::uint64_t>(half_span) || !analyse(centre)) {
    alpha_valid = false;
    tracking = false;
    return out;
  }
  score_candidates(alpha_next);
  const std::size_t n = alpha.size();
  if (alpha_valid) {
    const double gate_hz = cfg.max_slew_hz_per_s * cfg.hop_s;
    const int g = static_cast<int>(std::ceil(gate_hz / df)) + 1;
    const double global = *std::max_element(alpha.begin(), alpha.end()) - kJumpPenalty;
    // Sliding maximum over the slew gate (n is a few hundred, g a few tens).
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t lo = k >= static_cast<std::size_t>(g) ? k - static_cast<std::size_t>(g) : 0;
      const std::size_t hi = std::min(n - 1, k + static_cast<std::size_t>(g));
      const double local = *std::max_element(alpha.begin() + static_cast<std::ptrdiff_t>(lo),
                                             alpha.begin() + static_cast<std::ptrdiff_t>(hi) + 1);
      alpha_next[k] += kMemory * std::max(local, global);
    }
  }
  alpha.swap(alpha_next);
  alpha_valid = true;
  const auto best = static_cast<int>(std::max_element(alpha.begin(), alpha.end()) - alpha.begin());
  const double f0 = peak_near(best + k_lo, 3) * df;
  const Evidence ev = refine(f0);
  out.snr_db = ev.snr_db;

  const double since = std::isfinite(last_tracked_t) ? out.t - last_tracked_t : 1e9;
  const double gap = std::isfinite(cand_t) ? out.t - cand_t : 1e9;
  // Evidence accumulates along a run of mutually consistent estimates (tracked or not), starting from
  // zero: one lucky hop of noise cannot acquire, a fixed tone never builds a ladder.
  const bool consistent = gap <= kCoastS + 1e-9 && std::abs(ev.freq - cand_freq) <= slew_gate(gap);
  if (!consistent) {
    // Right after an engine was seen (a gear shift moves its line faster than the slew gate; an engine
    // rising from idle leaves the octave check), its ladder evidence carries over to the new line.
    // Only downwards (an up-shift) or into the bottom of the band (leaving idle): a fan elsewhere must
    // not inherit the engine's evidence when the engine stops.
    const bool engine_recent = std::isfinite(engine_t) && out.t - engine_t <= kCarryS + 1e-9 &&
                               (ev.freq < engine_freq || ev.freq < cfg.band_lo_hz + kIdleExitHz);
    ladder_acc = engine_recent ? std::max(ladder_acc, engine_ladder) * kCarry : 0.0;
    carried = engine_recent;
    snr_acc = half_acc = 0.0;
    cand_hops = 0;
  }
  half_acc = kLadderMemory * half_acc + (1.0 - kLadderMemory) * ev.snr[0];
  ladder_acc = kLadderMemory * ladder_acc + (1.0 - kLadderMemory) * ev.ladder_excess;
  snr_acc = kLadderMemory * snr_acc + (1.0 - kLadderMemory) * ev.snr[1];
  ++cand_hops;
  cand_freq = ev.freq;
  cand_t = out.t;
  // A half order stronger than the "fundamental" means the line is the 2nd harmonic of an engine
  // turning below the band (idle).
  const bool octave = ev.available[0] && half_acc > snr_acc;
  const bool ladder_keep = !cfg.require_harmonics || ladder_acc >= kKeepLadder;
  const bool ladder_acquire =
      !cfg.require_harmonics || ladder_acc >= (carried ? kReacquireLadder : kAcquireLadder);
  const bool keep = tracking && since <= kCoastS + 1e-9 &&
                    (std::abs(ev.freq - last_freq) <= slew_gate(since) ||
                     (ev.snr[1] >= kAcquireSnr && std::abs(ev.freq - last_freq) <= shift_gate(since))) &&
                    snr_acc >= kKeepSnr && ev.snr[1] >= kKeepSnrNow && ladder_keep && !octave;
  // The run's mean SNR (the exponential average corrected for its start from zero).
  const double snr_mean = snr_acc / (1.0 - std::pow(kLadderMemory, cand_hops));
  const bool acquire =
      cand_hops >= 2 && snr_mean >= kAcquireSnr && ev.snr[1] >= kKeepSnr && ladder_acquire && !octave;
  if (ladder_acc >= kAcquireLadder && snr_mean >= kAcquireSnr) {
    engine_t = out.t;
    engine_ladder = ladder_acc;
    engine_freq = octave ? ev.freq / 2.0 : ev.freq;
  }
#ifdef GEARPULSE_TRACKER_DEBUG
  std::fprintf(stderr, "t %.2f f %.2f snr %.1f %.1f %.1f %.1f lad %.1f acc %.1f %.1f keep %d acq %d\n", out.t,
               ev.freq, ev.snr[0], ev.snr[1], ev.snr[2], ev.snr[3], ev.ladder_excess, ladder_acc, snr_acc,
               keep, acquire);
#endif
  const bool in_band = ev.freq >= cfg.band_lo_hz - df && ev.freq <= cfg.band_hi_hz + df;
  if ((keep || acquire) && in_band) {
    out.freq = ev.freq;
    out.tracked = true;
    tracking = true;
    last_freq = ev.freq;
    last_tracked_t = out.t;
  } else if (since > kCoastS) {
    tracking = false;
  }
  return out;
}

void SlidingDftTracker::Impl::emit(const TrackPoint& p) noexcept {
  if (q_size == queue.size()) {
    q_head = (q_head + 1) % queue.size();
    --q_size;
    ++dropped;
  }
  queue[(q_head + q_size) % queue.size()] = p;
  ++q_size;
  history[(h_head + h_size) % history.size()] = p;
  if (h_size == history.size())
    h_head = (h_head + 1) % history.size();
  else
    ++h_size;
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
  if (!finite(c.max_slew_hz_per_s) || c.max_slew_hz_per_s < 0)
    return format("max slew %g Hz/s is not a non-negative number", c.max_slew_hz_per_s);
  if (!finite(c.shift_slew_hz_per_s) || c.shift_slew_hz_per_s < 0)
    return format("shift slew %g Hz/s is not a non-negative number", c.shift_slew_hz_per_s);
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
  s.n_in = 0;
  s.valid_from = 0;
  const auto first_hop = (s.half_span + s.hop_frames - 1) / s.hop_frames;
  s.next_centre = static_cast<std::uint64_t>(first_hop * s.hop_frames);
  s.alpha_valid = false;
  s.tracking = false;
  s.last_freq = kNaN;
  s.last_tracked_t = kNaN;
  s.ladder_acc = s.snr_acc = s.half_acc = 0.0;
  s.cand_freq = s.cand_t = kNaN;
  s.cand_hops = 0;
  s.carried = false;
  s.engine_t = kNaN;
  s.engine_ladder = 0.0;
  s.q_head = s.q_size = 0;
  s.h_head = s.h_size = 0;
}

void SlidingDftTracker::retime(double t_next) noexcept {
  impl_->t0 = t_next - static_cast<double>(impl_->n_in) / impl_->fs;
}

void SlidingDftTracker::skip(std::uint64_t frames) noexcept {
  Impl& s = *impl_;
  if (frames == 0) return;
  s.n_in += frames;
  s.valid_from = s.n_in;
  s.alpha_valid = false;
  s.tracking = false;
  // Hops whose windows overlap the hole give no output; resume on the hop grid after it.
  const auto h = static_cast<std::uint64_t>(s.hop_frames);
  const std::uint64_t min_centre = s.valid_from + static_cast<std::uint64_t>(s.half_span);
  if (s.next_centre < min_centre) s.next_centre = (min_centre + h - 1) / h * h;
}

void SlidingDftTracker::push(std::span<const float> frames) noexcept {
  Impl& s = *impl_;
  std::size_t i = 0;
  while (i < frames.size()) {
    const std::uint64_t needed = s.next_centre + static_cast<std::uint64_t>(s.half_span) + 1;
    while (i < frames.size() && s.n_in < needed)
      s.write_frame(frames[i++]);
    if (s.n_in >= needed) {
      s.emit(s.process_hop(s.next_centre));
      s.next_centre += static_cast<std::uint64_t>(s.hop_frames);
    }
  }
}

bool SlidingDftTracker::pop(TrackPoint& out) noexcept {
  Impl& s = *impl_;
  if (s.q_size == 0) return false;
  out = s.queue[s.q_head];
  s.q_head = (s.q_head + 1) % s.queue.size();
  --s.q_size;
  return true;
}

TrackPoint SlidingDftTracker::at(double t) noexcept {
  Impl& s = *impl_;
  TrackPoint out;
  out.t = t;
  const double pos = (t - s.t0) * s.fs;
  if (!std::isfinite(pos)) return out;
  const double c = std::round(pos);
  const auto hs = static_cast<double>(s.half_span);
  const double oldest = std::max(static_cast<double>(s.valid_from),
                                 static_cast<double>(s.n_in) - static_cast<double>(s.ring_size) + 1.0);
  if (c - hs < oldest || c + hs >= static_cast<double>(s.n_in)) return out;
  const auto centre = static_cast<std::uint64_t>(c);
  out.t = s.time_of(c);
  // Prior: the nearest tracked hop within the coast time.
  double prior = kNaN, prior_dt = 1e9;
  for (std::size_t k = 0; k < s.h_size; ++k) {
    const TrackPoint& h = s.history[(s.h_head + k) % s.history.size()];
    if (h.tracked && std::abs(h.t - out.t) < prior_dt) {
      prior_dt = std::abs(h.t - out.t);
      prior = h.freq;
    }
  }
  if (!std::isfinite(prior) || prior_dt > kCoastS || !s.analyse(centre)) return out;
  const double gate = s.cfg.max_slew_hz_per_s * prior_dt + 2.0 * s.df + 1.0;
  // Best harmonic score inside the gate around the prior.
  const int lo = std::max(s.k_lo, static_cast<int>(std::floor((prior - gate) / s.df)));
  const int hi = std::min(s.k_hi, static_cast<int>(std::ceil((prior + gate) / s.df)));
  if (lo > hi) return out;
  s.score_candidates(s.alpha_next);
  int best = lo;
  for (int k = lo; k <= hi; ++k)
    if (s.alpha_next[static_cast<std::size_t>(k - s.k_lo)] >
        s.alpha_next[static_cast<std::size_t>(best - s.k_lo)])
      best = k;
  const Impl::Evidence ev = s.refine(s.peak_near(best, 3) * s.df);
  out.snr_db = ev.snr_db;
  if (ev.snr[1] >= kKeepSnr && std::abs(ev.freq - prior) <= gate) {
    out.freq = ev.freq;
    out.tracked = true;
  }
  return out;
}

TrackPoint SlidingDftTracker::nearest(double t) const noexcept {
  const Impl& s = *impl_;
  TrackPoint best;
  best.t = t;
  double best_dt = 0.5 * s.cfg.hop_s + 1e-9;
  for (std::size_t k = 0; k < s.h_size; ++k) {
    const TrackPoint& h = s.history[(s.h_head + k) % s.history.size()];
    if (std::abs(h.t - t) <= best_dt) {
      best_dt = std::abs(h.t - t);
      best = h;
    }
  }
  return best;
}

double SlidingDftTracker::latest_time() const noexcept {
  const Impl& s = *impl_;
  const auto last = static_cast<std::int64_t>(s.n_in) - 1 - s.half_span;
  if (last < static_cast<std::int64_t>(s.valid_from) + s.half_span) return kNaN;
  return s.time_of(static_cast<double>(last));
}

const TrackerConfig& SlidingDftTracker::config() const noexcept {
  return impl_->cfg;
}
double SlidingDftTracker::decimated_rate_hz() const noexcept {
  return impl_->fd;
}
std::size_t SlidingDftTracker::queue_capacity() const noexcept {
  return impl_->queue.size();
}
std::size_t SlidingDftTracker::history_size() const noexcept {
  return impl_->history.size();
}
std::uint64_t SlidingDftTracker::dropped_outputs() const noexcept {
  return impl_->dropped;
}

}  // namespace gearpulse
