// Auto fit, the lag search: the time offset between the speed channel and engine speed that makes the gear
// lines of log(v/s) sharpest, and the speeds moved to it (aligned_channels).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>

#include "core/auto_estimator_internal.hpp"

namespace gearpulse::detail {
namespace {

// The sample at or before `target`, walking from sample k only over steps of time forward within
// max_gap (joined logs restart their clocks: a walk across one would read another log, and could cross
// all of it); nullopt where the walk meets such a step or target lies before the first sample.
std::optional<std::size_t> sample_at_or_before(const MixtureData& d, std::size_t k, double target,
                                               double max_gap) {
  const std::size_t n = d.size();
  auto step_ok = [&](std::size_t i) { return d.t[i + 1] - d.t[i] > 0.0 && d.t[i + 1] - d.t[i] <= max_gap; };
  std::size_t a = k;
  while (a + 1 < n && d.t[a + 1] <= target) {
    if (!step_ok(a)) return std::nullopt;
    ++a;
  }
  while (a > 0 && d.t[a] > target) {
    if (!step_ok(a - 1)) return std::nullopt;
    --a;
  }
  if (d.t[a] > target) return std::nullopt;
  return a;
}

// Speed read at a time offset from engine speed: v interpolated linearly to t + delta between the two
// samples around it (no change at the ends or across a gap).
double shifted_speed(const MixtureData& d, std::size_t k, double delta, double max_gap) {
  if (delta == 0.0) return d.v[k];
  const double target = d.t[k] + delta;
  const auto a = sample_at_or_before(d, k, target, max_gap);
  if (!a) return d.v[k];
  if (d.t[*a] == target) return std::max(0.0, d.v[*a]);
  const std::size_t b = *a + 1;
  if (b >= d.size()) return d.v[k];
  const double dt = d.t[b] - d.t[*a];
  if (!(dt > 0.0) || dt > max_gap) return d.v[k];  // a gap, or time restarting
  return std::max(0.0, d.v[*a] + (d.v[b] - d.v[*a]) * (target - d.t[*a]) / dt);
}

constexpr std::size_t kSearchTaps = 6;
using SearchKernel = std::array<double, kSearchTaps>;

// The lag search's reading (search_speed below) as weights on six samples at times x from the instant
// read (ascending, none at 0); nullopt when the spacing leaves more than twice a sample's noise (a step
// much shorter than its neighbours).
std::optional<SearchKernel> search_kernel(std::array<double, kSearchTaps> x) {
  const double scale = std::max(-x[0], x[kSearchTaps - 1]);
  for (double& xj : x)
    xj /= scale;
  // Lagrange weights of the cubic through the middle four, at x = 0.
  SearchKernel w{};
  for (std::size_t j = 1; j + 1 < kSearchTaps; ++j) {
    w[j] = 1.0;
    for (std::size_t i = 1; i + 1 < kSearchTaps; ++i)
      if (i != j) w[j] *= -x[i] / (x[j] - x[i]);
  }
  // The quartic contrast: x^4 made orthogonal to 1, x, x^2 and x^3 on the six points (Gram-Schmidt),
  // unit length. An even pattern: it leaves every cubic read exactly, and its amount is the same for an
  // offset and its mirror.
  std::array<SearchKernel, 5> basis{};
  for (std::size_t m = 0; m < 5; ++m) {
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      basis[m][j] = m == 0 ? 1.0 : basis[m - 1][j] * x[j];  // degree m: orthogonalised, as x^m would be
    for (std::size_t i = 0; i < m; ++i) {
      double dot = 0.0;
      for (std::size_t j = 0; j < kSearchTaps; ++j)
        dot += basis[m][j] * basis[i][j];
      for (std::size_t j = 0; j < kSearchTaps; ++j)
        basis[m][j] -= dot * basis[i][j];
    }
    double norm = 0.0;
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      norm += basis[m][j] * basis[m][j];
    norm = std::sqrt(norm);
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      basis[m][j] /= norm;
  }
  const SearchKernel& u = basis[4];
  double wu = 0.0;
  double ww = 0.0;
  for (std::size_t j = 0; j < kSearchTaps; ++j) {
    wu += w[j] * u[j];
    ww += w[j] * w[j];
  }
  // (w + alpha u)^2 = 1, the root nearer zero. Uneven spacing can leave no root: the contrast then only
  // lowers the sum of squares as far as it goes.
  const double disc = wu * wu + 1.0 - ww;
  const double alpha = disc >= 0.0 ? -wu + (wu > 0.0 ? std::sqrt(disc) : -std::sqrt(disc)) : -wu;
  double sum_sq = 0.0;
  for (std::size_t j = 0; j < kSearchTaps; ++j) {
    w[j] += alpha * u[j];
    sum_sq += w[j] * w[j];
  }
  if (!(sum_sq <= 2.0)) return std::nullopt;
  return w;
}

// Speed at t_k + delta for the lag search, from the six samples around that time: the cubic through the
// middle four, evaluated there, plus as much of the six's quartic contrast (the pattern no cubic shows)
// as brings the weights' sum of squares back to one, the amount nearer zero. On a regular grid every
// offset then carries a whole sample's noise, as the unshifted speeds do; a speed curve's slope, bend and
// jerk are read alike at every offset; and the reading moves smoothly with the offset, mirror-alike about
// the middle between two samples. Plain linear interpolation does none of this: it halves the noise half
// a sample away, which sharpens the lines by itself (with a drive's own asymmetries that passed for a lag
// in drives without any, 0.125-0.5 s at 1 Hz), and it cuts every bend short there. NaN where the six
// samples are not there or straddle a gap or a restart of the clock.
double search_speed(const MixtureData& d, std::size_t k, double delta, double max_gap) {
  constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  const double target = d.t[k] + delta;
  const auto at = sample_at_or_before(d, k, target, max_gap);
  if (!at || *at < 2 || *at + 3 >= d.size()) return kNone;
  const std::size_t a = *at;
  if (d.t[a] == target) return d.v[a];  // on a sample: the sample itself
  std::array<double, kSearchTaps> x{};  // times of samples a-2 .. a+3 from target
  for (std::size_t j = 0; j < kSearchTaps; ++j) {
    x[j] = d.t[a - 2 + j] - target;
    if (j > 0 && !(x[j] - x[j - 1] > 0.0 && x[j] - x[j - 1] <= max_gap)) return kNone;
  }
  const auto w = search_kernel(x);
  if (!w) return kNone;
  double v = 0.0;
  for (std::size_t j = 0; j < kSearchTaps; ++j)
    v += (*w)[j] * d.v[a - 2 + j];
  return v;
}

// Sharpness of the log(v/s) density (sum of squared bin shares, a collision probability) over the
// samples [begin, end): gear lines give narrow peaks, a misaligned speed channel smears them in
// proportion to the acceleration.
double ratio_sharpness(const MixtureData& d, std::size_t begin, std::size_t end, double delta, double gap,
                       double max_gap) {
  constexpr double kBin = 0.015;  // log units, the middle smoothing width of candidate_scales
  std::vector<double> keys;
  keys.reserve(end - begin);
  // On a regular grid of step `gap` every sample is read with the same weights: computed once here,
  // used wherever the six samples sit on that grid, the general reading elsewhere.
  const double rows = std::floor(delta / gap);
  const double frac = delta / gap - rows;
  std::optional<SearchKernel> regular;
  if (frac > 1e-9 && frac < 1.0 - 1e-9) {
    std::array<double, kSearchTaps> x{};
    for (std::size_t j = 0; j < kSearchTaps; ++j)
      x[j] = (static_cast<double>(j) - 2.0 - frac) * gap;
    regular = search_kernel(x);
  }
  const auto shift = static_cast<std::ptrdiff_t>(rows);
  auto on_grid = [&](std::size_t k) {
    const std::ptrdiff_t a = static_cast<std::ptrdiff_t>(k) + shift;
    if (a < 2 || a + 3 >= static_cast<std::ptrdiff_t>(d.size())) return false;
    for (std::ptrdiff_t j = -2; j <= 3; ++j)
      if (std::abs(d.t[static_cast<std::size_t>(a + j)] - (d.t[k] + (rows + static_cast<double>(j)) * gap)) >
          1e-6 * gap)
        return false;
    return true;
  };
  for (std::size_t k = begin; k < end; ++k) {
    double v = 0.0;
    if (regular && on_grid(k)) {
      const std::size_t a = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(k) + shift);
      for (std::size_t j = 0; j < kSearchTaps; ++j)
        v += (*regular)[j] * d.v[a - 2 + j];
    } else {
      v = search_speed(d, k, delta, max_gap);
    }
    if (v > kMovingSpeed && d.s[k] > 0.0) keys.push_back(std::floor(std::log(v / d.s[k]) / kBin));
  }
  if (keys.empty()) return 0.0;
  std::sort(keys.begin(), keys.end());
  double sum = 0.0;
  std::size_t run = 1;
  for (std::size_t i = 1; i <= keys.size(); ++i) {
    if (i < keys.size() && keys[i] == keys[i - 1]) {
      ++run;
      continue;
    }
    sum += static_cast<double>(run) * static_cast<double>(run);
    run = 1;
  }
  const double n = static_cast<double>(keys.size());
  return sum / (n * n);
}

}  // namespace

// A logger that reads speed and engine speed at different instants (OBD-II polls its PIDs in turn and
// the ECU's speed may lag; a GPS fix is reported after the audio it belongs to, by up to a second or
// so whatever the fix rate) pairs them with a time offset; at acceleration a the speed is then off by
// a * offset, in first gear as much as the step between gears. The offset, searched over +-kLagSearch
// (2 s, or one sampling interval if longer), coarse then fine, is the one that makes the gear lines
// sharpest; the speeds are moved to it. The search looks at a contiguous stretch of at most kAlignSamples
// samples (enough to see the lag, and it keeps a week-long log fast). Without time stamps nothing changes.
Aligned aligned_channels(const MixtureData& all) {
  constexpr double kLagSearch = 2.0;             // s: offsets searched, -kLagSearch to +kLagSearch
  constexpr std::size_t kAlignSamples = 200000;  // samples the search looks at
  const std::size_t n = all.size();
  if (all.t.size() != n || n < 30) return {all, 0.0};
  std::vector<double> gaps;
  for (std::size_t k = 1; k < n; ++k) {
    const double dt = all.t[k] - all.t[k - 1];
    if (dt > 0.0) gaps.push_back(dt);
  }
  if (gaps.size() < n / 2) return {all, 0.0};
  std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2), gaps.end());
  const double gap = gaps[gaps.size() / 2];
  const double max_gap = 3.0 * gap;
  const std::size_t begin = n > kAlignSamples ? (n - kAlignSamples) / 2 : 0;
  const std::size_t end = std::min(n, begin + kAlignSamples);
  auto sharpness = [&](double delta) {
    throw_if_stopped(all);
    return ratio_sharpness(all, begin, end, delta, gap, max_gap);
  };
  const double unshifted = sharpness(0.0);
  const double range = std::max(kLagSearch, gap);
  const double coarse = range / 8.0;
  double best_delta = 0.0;
  double best = unshifted;
  for (int step = -8; step <= 8; ++step) {
    const double delta = coarse * step;
    const double sharp = step == 0 ? unshifted : sharpness(delta);
    if (sharp > best) {
      best = sharp;
      best_delta = delta;
    }
  }
  // Refine around the optimum in finer steps, down to an eighth of a sampling interval or 1/32 s,
  // whichever is finer (at 1 Hz an eighth, 0.125 s, left first gear 2 % off in launches).
  const double finest = std::min(gap / 8.0, 1.0 / 32.0);
  for (double step = coarse / 8.0, width = coarse; width > finest + 1e-12; width = step, step /= 8.0) {
    step = std::max(step, finest);
    const double centre = best_delta;
    for (int i = -7; i <= 7; ++i) {
      const double delta = centre + i * step;
      if (i == 0 || std::abs(delta - centre) >= width || std::abs(delta) > range + 1e-9) continue;
      const double sharp = sharpness(delta);
      if (sharp > best) {
        best = sharp;
        best_delta = delta;
      }
    }
  }
  // A few percent of sharpness is what sampling noise alone gives. The search's speeds carry the same
  // noise at every offset (search_speed), and a shift must also beat its mirror: a gain the opposite
  // shift shares is no lag's.
  const double mirror = best_delta != 0.0 ? sharpness(-best_delta) : unshifted;
  if (best < 1.05 * std::max(unshifted, mirror)) return {all, 0.0};
  Aligned out{all, best_delta};
  for (std::size_t k = 0; k < n; ++k)
    out.data.v[k] = shifted_speed(all, k, best_delta, max_gap);
  return out;
}

}  // namespace gearpulse::detail
