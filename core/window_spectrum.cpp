#include "core/window_spectrum.hpp"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <numbers>
#include <stdexcept>

namespace gearpulse {
namespace {

constexpr int kNoiseBlock = 192;  // fine bins per noise-floor block

// The FFTW planner is not thread-safe; trackers may be built on several threads.
std::mutex& planner_mutex() {
  static std::mutex m;
  return m;
}

}  // namespace

WindowSpectrum::WindowSpectrum(int n, int nfft, int noise_lo, int noise_hi)
    : n_(n), nfft_(nfft), noise_lo_(noise_lo), noise_hi_(noise_hi), taper_(static_cast<std::size_t>(n)) {
  for (int i = 0; i < n_; ++i) {
    const double w = 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * (i + 1) / (n_ + 1));
    taper_[static_cast<std::size_t>(i)] = w;
    sum_w2_ += w * w;
  }
  const auto bins = static_cast<std::size_t>(nfft_ / 2 + 1);
  in_.reset(static_cast<double*>(fftw_malloc(sizeof(double) * static_cast<std::size_t>(nfft_))));
  out_.reset(static_cast<fftw_complex*>(fftw_malloc(sizeof(fftw_complex) * bins)));
  resid_in_.reset(static_cast<double*>(fftw_malloc(sizeof(double) * static_cast<std::size_t>(nfft_))));
  resid_out_.reset(static_cast<fftw_complex*>(fftw_malloc(sizeof(fftw_complex) * bins)));
  if (!in_ || !out_ || !resid_in_ || !resid_out_) throw std::bad_alloc();
  {
    const std::lock_guard lock(planner_mutex());
    plan_ = fftw_plan_dft_r2c_1d(nfft_, in_.get(), out_.get(), FFTW_ESTIMATE);
  }
  if (!plan_) throw std::runtime_error("SlidingDftTracker: FFTW could not make a plan");
  std::fill(in_.get(), in_.get() + nfft_, 0.0);
  std::fill(resid_in_.get(), resid_in_.get() + nfft_, 0.0);
  power_.assign(bins, 0.0);
  noise_.assign(bins, 0.0);
  scratch_.assign(bins, 0.0);
}

WindowSpectrum::~WindowSpectrum() {
  const std::lock_guard lock(planner_mutex());
  fftw_destroy_plan(plan_);
}

bool WindowSpectrum::analyse(double* samples) noexcept {
  const int mid = (n_ - 1) / 2;
  // Least-squares line removal: the supply level and its slow drift are not the ripple.
  double s0 = 0.0, s1 = 0.0, s2 = 0.0;
  for (int j = 0; j < n_; ++j) {
    const double m = j - mid;
    s0 += samples[j];
    s1 += m * samples[j];
    s2 += m * m;
  }
  const double mean = s0 / n_;
  const double slope = s2 > 0 ? s1 / s2 : 0.0;
  double energy = 0.0, level = 0.0;
  for (int j = 0; j < n_; ++j) {
    const auto i = static_cast<std::size_t>(j);
    level = std::max(level, std::abs(samples[j]));
    const double v = (samples[j] - mean - slope * (j - mid)) * taper_[i];
    samples[j] = v;
    in_.get()[i] = v;
    energy += v * v;
  }
  if (!(energy > 1e-20 * std::max(1.0, level * level * n_)) || !std::isfinite(energy)) return false;
  fftw_execute_dft_r2c(plan_, in_.get(), out_.get());
  const int bins = nfft_ / 2 + 1;
  for (int k = 0; k < bins; ++k) {
    const auto i = static_cast<std::size_t>(k);
    power_[i] = out_.get()[i][0] * out_.get()[i][0] + out_.get()[i][1] * out_.get()[i][1];
  }
  // Noise floor: lower quartile per block of fine bins (robust to the lines of the engine and of other
  // equipment), as the mean of an exponential variable (q25 / ln(4/3)), interpolated linearly between block
  // centres (coloured noise).
  const int span = noise_hi_ - noise_lo_ + 1;
  const int blocks = std::max(1, span / kNoiseBlock);
  const double block_len = static_cast<double>(span) / blocks;
  double prev_centre = 0.0, prev_level = 0.0;
  for (int b = 0; b < blocks; ++b) {
    const int lo = noise_lo_ + static_cast<int>(std::lround(b * block_len));
    const int hi = noise_lo_ + static_cast<int>(std::lround((b + 1) * block_len));
    const auto n = static_cast<std::size_t>(hi - lo);
    std::copy(power_.begin() + lo, power_.begin() + hi, scratch_.begin());
    std::nth_element(scratch_.begin(), scratch_.begin() + static_cast<std::ptrdiff_t>(n / 4),
                     scratch_.begin() + static_cast<std::ptrdiff_t>(n));
    const double level_b = std::max(scratch_[n / 4] / std::log(4.0 / 3.0), 1e-300);
    const double centre_b = 0.5 * (lo + hi);
    if (b == 0) {
      for (int k = 0; k <= static_cast<int>(centre_b); ++k)
        noise_[static_cast<std::size_t>(k)] = level_b;
    } else {
      for (int k = static_cast<int>(prev_centre) + 1; k <= static_cast<int>(centre_b); ++k) {
        const double a = (k - prev_centre) / (centre_b - prev_centre);
        noise_[static_cast<std::size_t>(k)] = prev_level + a * (level_b - prev_level);
      }
    }
    prev_centre = centre_b;
    prev_level = level_b;
  }
  for (int k = static_cast<int>(prev_centre) + 1; k < bins; ++k)
    noise_[static_cast<std::size_t>(k)] = prev_level;
  return true;
}

const fftw_complex* WindowSpectrum::transform_residual() noexcept {
  fftw_execute_dft_r2c(plan_, resid_in_.get(), resid_out_.get());
  return resid_out_.get();
}

}  // namespace gearpulse
