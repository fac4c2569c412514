#include "core/sinusoid_fit.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace gearpulse {
namespace {

// Sums over m = -h..h (a window of 2h + 1 samples centred on m = 0) in closed form, for the Gram matrix
// of the fit's columns: sum of cos(m theta) (the Dirichlet kernel) and sum of m sin(m theta) (minus its
// derivative).
double sum_cos(int h, double theta) noexcept {
  const double s = std::sin(0.5 * theta);
  if (std::abs(s) < 1e-9) return 2.0 * h + 1.0;
  return std::sin((h + 0.5) * theta) / s;
}

double sum_m_sin(int h, double theta) noexcept {
  const double s = std::sin(0.5 * theta);
  if (std::abs(s) < 1e-3) {  // the closed form cancels near theta = 0
    double sum = 0.0;
    for (int m = 1; m <= h; ++m)
      sum += 2.0 * m * std::sin(m * theta);
    return sum;
  }
  const double a = (h + 0.5) * theta;
  return -((h + 0.5) * std::cos(a) * s - 0.5 * std::sin(a) * std::cos(0.5 * theta)) / (s * s);
}

}  // namespace

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
  // Projections of y on the columns (level, slope, cos and sin of each sinusoid), summed.
  const double scale = 1.0 / std::max(1, mid);
  for (int j = 0; j < n_; ++j) {
    const double yj = y[j];
    rhs[0] += yj;
    rhs[1] += static_cast<double>(j - mid) * scale * yj;
    for (int o = 0; o < kMaxSines; ++o) {
      if (col[o] < 0) continue;
      rhs[col[o]] += phasor[o].real() * yj;
      rhs[col[o] + 1] += phasor[o].imag() * yj;
      phasor[o] *= rot[o];
    }
  }
  // The columns' Gram matrix in closed form (the window is symmetric about m = 0, so the level is
  // orthogonal to the slope and to every sine, the slope to every cosine, and every cosine to every sine).
  gram[0][0] = n_;
  gram[1][1] = static_cast<double>(mid) * (mid + 1) * (2.0 * mid + 1) / 3.0 * scale * scale;
  for (int o = 0; o < kMaxSines; ++o) {
    const int a = col[o];
    if (a < 0) continue;
    const double wa = 2.0 * std::numbers::pi * freq_hz[o] / rate_;
    gram[a][0] = sum_cos(mid, wa);
    gram[a + 1][1] = sum_m_sin(mid, wa) * scale;
    for (int p = 0; p <= o; ++p) {
      const int b = col[p];
      if (b < 0) continue;
      const double wb = 2.0 * std::numbers::pi * freq_hz[p] / rate_;
      const double minus = sum_cos(mid, wa - wb), plus = sum_cos(mid, wa + wb);
      gram[a][b] = 0.5 * (minus + plus);
      gram[a + 1][b + 1] = 0.5 * (minus - plus);
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
