#pragma once
// The spectrum of one decimated window for the engine-frequency tracker: the window detrended (the
// supply level and its slow drift are not the ripple), Hann-tapered and zero-padded, its power per fine
// bin, and the noise floor per fine bin (the lower quartile of blocks of bins, robust to lines). Also the
// transform of a residual (what a fitted model leaves of the window). FFTW plans and buffers are made at
// construction (which may throw); analyse() and transform_residual() never allocate, lock or throw.
#include <fftw3.h>

#include <cstddef>
#include <memory>
#include <vector>

namespace gearpulse {

class WindowSpectrum {
 public:
  // Windows of n samples (odd), transformed over nfft points; the noise floor is read over the fine bins
  // noise_lo..noise_hi.
  WindowSpectrum(int n, int nfft, int noise_lo, int noise_hi);
  ~WindowSpectrum();
  WindowSpectrum(const WindowSpectrum&) = delete;
  WindowSpectrum& operator=(const WindowSpectrum&) = delete;

  // Detrends and tapers `samples` (n) in place, then fills power() and noise(). False on a silent window.
  bool analyse(double* samples) noexcept;
  [[nodiscard]] const std::vector<double>& power() const noexcept { return power_; }
  [[nodiscard]] const std::vector<double>& noise() const noexcept { return noise_; }
  [[nodiscard]] const std::vector<double>& taper() const noexcept { return taper_; }
  [[nodiscard]] double taper_energy() const noexcept { return sum_w2_; }  // sum of the taper's squares

  // The residual's n tapered samples are written here, then transformed by transform_residual().
  [[nodiscard]] double* residual() noexcept { return resid_in_.get(); }
  [[nodiscard]] const fftw_complex* transform_residual() noexcept;
  // Scratch of nfft / 2 + 1 values, free between calls.
  [[nodiscard]] double* scratch() noexcept { return scratch_.data(); }

 private:
  struct FftwFree {
    void operator()(void* p) const noexcept { fftw_free(p); }
  };
  int n_, nfft_, noise_lo_, noise_hi_;
  std::vector<double> taper_;
  double sum_w2_ = 0.0;
  std::unique_ptr<double, FftwFree> in_;
  std::unique_ptr<fftw_complex, FftwFree> out_;
  std::unique_ptr<double, FftwFree> resid_in_;
  std::unique_ptr<fftw_complex, FftwFree> resid_out_;
  fftw_plan plan_ = nullptr;
  std::vector<double> power_, noise_, scratch_;
};

}  // namespace gearpulse
