#pragma once
// Least-squares model of one decimated window for the engine-frequency tracker: a level, a slope and a
// sinusoid at each of a few given frequencies (the engine's orders, a fixed tone beside them), fitted
// jointly, so that the orders do not leak into each other as they would through a window; its explained
// energy, maximised over the fundamental, is the ML estimate of a harmonic signal's frequency in white
// noise. The window is symmetric about its centre sample (n odd), so the columns' Gram matrix is summed in
// closed form and only the projections of the window cost a pass over it. Also the DTFT of a window and
// its derivatives. Nothing allocates, locks or throws.
#include <complex>

namespace gearpulse {

class SinusoidFit {
 public:
  static constexpr int kMaxSines = 5;
  static constexpr int kMaxCols = 2 + 2 * kMaxSines;
  struct Result {
    double coef[kMaxCols] = {};                 // level, slope, then cos and sin of each fitted sinusoid
    int col[kMaxSines] = {-1, -1, -1, -1, -1};  // first column of sinusoid i, -1 when not fitted
    int cols = 0;                               // 0: nothing fitted
  };

  // Windows of n samples (odd) at rate_hz.
  SinusoidFit(int n, double rate_hz) : n_(n), rate_(rate_hz) {}

  // Fits y (n samples) with a sinusoid at every freq_hz[i] that is finite (i < kMaxSines) and returns the
  // energy the model explains (0 when it is degenerate); writes the model to `out` when given and not
  // degenerate.
  double fit(const double* y, const double* freq_hz, Result* out) const noexcept;
  // (y - model) x taper into out (n samples).
  void residual(const double* y, const double* freq_hz, const Result& model, const double* taper,
                double* out) const noexcept;
  // DTFT of x (n samples, time origin at the centre) and its first two derivatives at omega (radians per
  // sample).
  void dtft(const double* x, double omega, std::complex<double>& value, std::complex<double>& d1,
            std::complex<double>& d2) const noexcept;

 private:
  int n_;
  double rate_;
};

}  // namespace gearpulse
