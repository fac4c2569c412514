#include "core/sinusoid_fit.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace gearpulse {

double SinusoidFit::fit(const double* y, const double* freq_hz, Result* out) const noexcept {
  double gram[kMaxCols][kMaxCols] = {};
  double rhs[kMaxCols] = {};
  std::complex<double> rot[kMaxSines], phasor[kMaxSines];
  int col[kMaxSines];
  int cols = 2;
  const int mid = (n_ - 1) / 2;
  for (int o = 0; o < kMaxSines; ++o) {
    col[o] = -1;
    if (!std::isfinite(freq_hz[o])) continue;
    col[o] = cols;
    cols += 2;
    const double w = 2.0 * std::numbers::pi * freq_hz[o] / rate_;
    rot[o] = std::polar(1.0, w);
    phasor[o] = std::polar(1.0, -w * mid);
  }
  double v[kMaxCols];
  for (int j = 0; j < n_; ++j) {
    v[0] = 1.0;
    v[1] = static_cast<double>(j - mid) / std::max(1, mid);
    for (int o = 0; o < kMaxSines; ++o) {
      if (col[o] < 0) continue;
      v[col[o]] = phasor[o].real();
      v[col[o] + 1] = phasor[o].imag();
      phasor[o] *= rot[o];
    }
    const double yj = y[j];
    for (int a = 0; a < cols; ++a) {
      rhs[a] += v[a] * yj;
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
  if (out) {
    for (int a = cols - 1; a >= 0; --a) {
      double sum = z[a];
      for (int k = a + 1; k < cols; ++k)
        sum -= l[k][a] * x[k];
      x[a] = sum / l[a][a];
    }
    out->cols = cols;
    std::copy(x, x + cols, out->coef);
    std::copy(col, col + kMaxSines, out->col);
  }
  return explained;
}

void SinusoidFit::residual(const double* y, const double* freq_hz, const Result& model, const double* taper,
                           double* out) const noexcept {
  const int mid = (n_ - 1) / 2;
  std::complex<double> rot[kMaxSines], phasor[kMaxSines];
  for (int o = 0; o < kMaxSines; ++o) {
    if (model.col[o] < 0) continue;
    const double w = 2.0 * std::numbers::pi * freq_hz[o] / rate_;
    rot[o] = std::polar(1.0, w);
    phasor[o] = std::polar(1.0, -w * mid);
  }
  for (int j = 0; j < n_; ++j) {
    double m = model.coef[0] + model.coef[1] * static_cast<double>(j - mid) / std::max(1, mid);
    for (int o = 0; o < kMaxSines; ++o) {
      const int c = model.col[o];
      if (c < 0) continue;
      m += model.coef[c] * phasor[o].real() + model.coef[c + 1] * phasor[o].imag();
      phasor[o] *= rot[o];
    }
    out[j] = (y[j] - m) * taper[j];
  }
}

void SinusoidFit::dtft(const double* x, double omega, std::complex<double>& value, std::complex<double>& d1,
                       std::complex<double>& d2) const noexcept {
  const int mid = (n_ - 1) / 2;
  const std::complex<double> step = std::polar(1.0, -omega);
  std::complex<double> e = std::polar(1.0, omega * mid);  // e^{-j omega m} at m = -mid
  value = d1 = d2 = 0.0;
  for (int j = 0; j < n_; ++j) {
    const double m = j - mid;
    const std::complex<double> v = x[j] * e;
    value += v;
    d1 += std::complex<double>(0.0, -m) * v;
    d2 += -m * m * v;
    e *= step;
  }
}

}  // namespace gearpulse
