#include "core/decimating_input.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace gearpulse {
namespace {

constexpr double kPi = std::numbers::pi;
// Decimated rate at least this multiple of the highest frequency held; stopband attenuation.
constexpr double kDecimationMargin = 2.4;
constexpr double kStopbandDb = 70.0;

double bessel_i0(double x) {
  double sum = 1.0, term = 1.0;
  for (int k = 1; k < 50; ++k) {
    term *= (x / (2.0 * k)) * (x / (2.0 * k));
    sum += term;
    if (term < 1e-17 * sum) break;
  }
  return sum;
}

}  // namespace

DecimatingInput::DecimatingInput(double fs_hz, double top_hz) {
  const double fs = fs_hz, top = top_hz;
  decim_ = std::max(1, static_cast<int>(std::floor(fs / (kDecimationMargin * top))));
  fd_ = fs / decim_;
  if (decim_ > 1) {
    // Kaiser-windowed sinc: passband up to `top`, stopband from fd - top (what would alias below top).
    const double transition = fd_ - 2.0 * top;
    const double beta = 0.1102 * (kStopbandDb - 8.7);
    int len = static_cast<int>(std::ceil((kStopbandDb - 8.0) / (2.285 * 2.0 * kPi * transition / fs))) + 1;
    if (len % 2 == 0) ++len;
    const double fc = 0.5 * fd_ / fs;  // cycles per input sample
    fir_.resize(static_cast<std::size_t>(len));
    const int mid = len / 2;
    double sum = 0.0;
    for (int i = 0; i < len; ++i) {
      const double m = i - mid;
      const double sinc = m == 0 ? 2.0 * fc : std::sin(2.0 * kPi * fc * m) / (kPi * m);
      const double r = m / mid;
      const double kaiser = bessel_i0(beta * std::sqrt(std::max(0.0, 1.0 - r * r))) / bessel_i0(beta);
      fir_[static_cast<std::size_t>(i)] = sinc * kaiser;
      sum += fir_[static_cast<std::size_t>(i)];
    }
    for (double& h : fir_)
      h /= sum;
    limit_hz_ = top;
  } else {
    fir_.assign(1, 1.0);
    limit_hz_ = 0.45 * fs;
  }
}

void DecimatingInput::reserve(std::size_t frames) {
  std::size_t p = 1;
  while (p < frames)
    p <<= 1;
  size_ = p;
  ring_.assign(2 * size_, 0.0f);
}

}  // namespace gearpulse
