#include "core/speed_lag.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace gearpulse {
namespace {

// m/s: slower, the clutch may still slip and first gear runs near idle: the revs do not follow a line.
constexpr double kMinSpeed = 3.0;
// Bound on a fix's log-departure from the nearest gear: 10 %, half the smallest step between the gears of
// a close-ratio box and more than a lag of a second makes of a car gaining speed at 1 m/s^2 beyond 10 m/s.
constexpr double kClip = 0.1;
// Fixes (those taken while the speed changes, a few a minute in town) the averages remember: the lag belongs
// to the receiver and the logger, fixed over a drive, so the memory is long; it lets a changed receiver's lag
// replace the old one within a drive or two rather than never.
constexpr double kMemory = 200.0;
// m/s^2: a change of speed between fixes that is the car's, not the receiver's noise (0.1-0.2 m/s a fix).
constexpr double kMinChange = 0.3;
// Fixes' worth (the weights' effective number) before a difference's spread is known well enough to judge
// it by: from 20, the spread's own relative error (1 / sqrt(2 n)) is under a sixth.
constexpr double kMinFixes = 20.0;

}  // namespace

void SpeedLag::History::add(double t, double value) noexcept {
  if (!std::isfinite(t) || !std::isfinite(value) || value < 0.0) return;
  if (size_ >= 2 && t - t_[static_cast<std::size_t>((next_ - 2 + kSize) % kSize)] < kSpacing)
    next_ = (next_ - 1 + kSize) % kSize;  // the newest is replaced (kSpacing)
  else
    size_ = std::min(size_ + 1, kSize);
  t_[static_cast<std::size_t>(next_)] = t;
  value_[static_cast<std::size_t>(next_)] = value;
  next_ = (next_ + 1) % kSize;
}

bool SpeedLag::History::at(double t, double& value) const noexcept {
  double after_t = std::numeric_limits<double>::infinity(), after = 0.0;
  for (int k = 1; k <= size_; ++k) {  // newest first
    const auto i = static_cast<std::size_t>((next_ - k + kSize) % kSize);
    if (t_[i] > t) {
      after_t = t_[i];
      after = value_[i];
      continue;
    }
    if (t_[i] == t) {
      value = value_[i];
      return true;
    }
    if (!std::isfinite(after_t) || after_t - t_[i] > kMaxGap) return false;
    value = value_[i] + (t - t_[i]) / (after_t - t_[i]) * (after - value_[i]);
    return true;
  }
  return false;
}

void SpeedLag::set_prior(double lag) noexcept {
  prior_ = std::isfinite(lag) ? std::clamp(lag, 0.0, kLongestLag) : 0.0;
  choose();
}

void SpeedLag::learn(double t, double gps, std::span<const double> theta) noexcept {
  const double fix_dt = t - last_t_, change = gps - last_gps_;
  last_t_ = t;
  last_gps_ = gps;
  // Only while the speed changes does a lag show (see the header).
  if (!std::isfinite(gps) || gps < kMinSpeed || theta.empty() || !(fix_dt > 0.0) || fix_dt > kMaxGap ||
      std::abs(change) < kMinChange * fix_dt)
    return;
  std::array<double, kCandidates> err{};
  for (int c = 0; c < kCandidates; ++c) {
    double f = 0.0;
    if (!revs_.at(t - c * kStep, f) || !(f > 0.0)) return;  // every candidate judged on the same fixes
    double best = kClip;
    for (const double th : theta)
      if (th > 0.0) best = std::min(best, std::abs(std::log(gps / (th * f))));
    err[static_cast<std::size_t>(c)] = best * best;
  }
  constexpr double kKeep = 1.0 - 1.0 / kMemory;
  for (std::size_t i = 0; i < err.size(); ++i) {
    cost_[i] = kKeep * cost_[i] + err[i];
    for (std::size_t j = 0; j < err.size(); ++j)
      cross_[i][j] = kKeep * cross_[i][j] + err[i] * err[j];
  }
  weight_ = kKeep * weight_ + 1.0;
  weight_sq_ = kKeep * kKeep * weight_sq_ + 1.0;
  choose();
}

void SpeedLag::choose() noexcept {
  int best = 0;
  for (int c = 1; c < kCandidates; ++c)
    if (cost_[static_cast<std::size_t>(c)] < cost_[static_cast<std::size_t>(best)]) best = c;
  double offset = 0.0;
  if (best > 0 && best < kCandidates - 1) {
    const double lo = cost_[static_cast<std::size_t>(best - 1)], mid = cost_[static_cast<std::size_t>(best)],
                 hi = cost_[static_cast<std::size_t>(best + 1)];
    const double curvature = lo - 2.0 * mid + hi;
    if (curvature > 0.0) offset = std::clamp(0.5 * (lo - hi) / curvature, -0.5, 0.5);
  }
  lag_ = (best + offset) * kStep;
  // Significance against the prior's candidate: the weighted mean difference of the departures and its
  // standard error over the weights' effective number of fixes.
  const auto p = static_cast<std::size_t>(std::lround(prior_ / kStep));
  const auto b = static_cast<std::size_t>(best);
  const double fixes = weight_sq_ > 0.0 ? weight_ * weight_ / weight_sq_ : 0.0;
  own_ = weight_ > 0.0 && b != p && significance_ <= 0.0;  // a first fix, not the prior's zero costs
  if (b == p || significance_ <= 0.0 || fixes < kMinFixes) return;
  const double gain = (cost_[p] - cost_[b]) / weight_;
  const double spread = (cross_[p][p] - 2.0 * cross_[p][b] + cross_[b][b]) / weight_ - gain * gain;
  own_ = gain > 0.0 && gain * gain * fixes >= significance_ * significance_ * std::max(spread, 0.0);
}

}  // namespace gearpulse
