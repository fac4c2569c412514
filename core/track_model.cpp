#include "core/track_model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace gearpulse {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Per second: the engine stops, starts, or its line is lost and found elsewhere.
constexpr double kStopRate = 0.05;
constexpr double kStartRate = 0.5;
constexpr double kJumpRate = 0.02;
// A continuing line moves within one of three gates per hop: steady (cruise: a few Hz/s), the slew of
// an accelerating engine, or a gear shift; shares of each.
constexpr double kSteadyHzPerS = 5.0;
constexpr double kSteadyShare = 0.5, kSlewShare = 0.4;  // the rest: shift
// Memory (per hop) of the track's drift, which moves the steady and slew gates.
constexpr double kDriftMemory = 0.7;
// An estimate is right within 5 % of the engine's fundamental; a confident one has 0.8 of the posterior
// there (the tracker's "tracked").
constexpr double kRightFraction = 0.05;
constexpr double kConfident = 0.8;

}  // namespace

TrackModel::TrackModel(const TrackerConfig& config, int first_bin, int last_bin, double df_hz, int lobe)
    : hop_s_(config.hop_s),
      max_slew_(config.max_slew_hz_per_s),
      temper_(std::min(1.0, config.hop_s / config.window_s)),
      first_(first_bin),
      last_(last_bin),
      df_(df_hz),
      lobe_(lobe) {
  const auto states = static_cast<std::size_t>(last_ - first_ + 1);
  post_.assign(states, 0.0);
  loglik_.assign(states, 0.0);
  cumsum_.assign(states + 1, 0.0);
  const double dt = hop_s_;
  gate_steady_ = static_cast<int>(std::ceil((kSteadyHzPerS * dt) / df_)) + 1;
  gate_slew_ = static_cast<int>(std::ceil((max_slew_ * dt) / df_)) + 2;
  gate_shift_ = static_cast<int>(std::ceil((std::max(max_slew_, config.shift_slew_hz_per_s) * dt) / df_)) + 2;
  p_stop_ = 1.0 - std::exp(-kStopRate * dt);
  p_start_ = 1.0 - std::exp(-kStartRate * dt);
  p_jump_ = 1.0 - std::exp(-kJumpRate * dt);
  reset();
}

void TrackModel::reset() noexcept {
  post_absent_ = 0.5;
  std::fill(post_.begin(), post_.end(), 0.5 / static_cast<double>(post_.size()));
  drift_hz_per_s_ = 0.0;
  last_freq_ = kNaN;
  anchor_freq_ = kNaN;
  anchor_age_ = 0;
}

// Prior of this hop from the previous posterior: a continuing line moves within a steady, a slew or a
// shift gate (box kernels by prefix sums); the engine may stop, start, or be found anywhere.
void TrackModel::predict() noexcept {
  const auto n = static_cast<int>(post_.size());
  cumsum_[0] = 0.0;
  for (int i = 0; i < n; ++i)
    cumsum_[static_cast<std::size_t>(i) + 1] =
        cumsum_[static_cast<std::size_t>(i)] + post_[static_cast<std::size_t>(i)];
  const double present = cumsum_[static_cast<std::size_t>(n)];
  const auto box = [&](int i, int g) {
    const int lo = std::max(0, i - g), hi = std::min(n - 1, i + g);
    if (lo > hi) return 0.0;
    return (cumsum_[static_cast<std::size_t>(hi) + 1] - cumsum_[static_cast<std::size_t>(lo)]) /
           (2.0 * g + 1.0);
  };
  // The steady and slew gates move with the track's recent drift (a ramping engine stays in its gate).
  const auto shift = static_cast<int>(std::lround(drift_hz_per_s_ * hop_s_ / df_));
  const double stay = 1.0 - p_stop_ - p_jump_;
  // The engine found again after the track lost it (a window smeared by a shift, a few drowned hops) is
  // where the latest tracked estimate could have ramped to since, at the slew, unless it stopped or was
  // found elsewhere meanwhile (the stop and jump rates). Without this a line found again after a lost hop
  // was as likely anywhere, and a loud 2nd harmonic there took the track for a hop at twice the engine.
  double near_share = 0.0;
  int near_lo = 0, near_hi = -1;
  if (std::isfinite(anchor_freq_)) {
    const double dt = (anchor_age_ + 1) * hop_s_;
    const double reach = max_slew_ * dt + std::max(kRightFraction * anchor_freq_, lobe_ * df_);
    near_lo = std::max(0, static_cast<int>(std::ceil((anchor_freq_ - reach) / df_)) - first_);
    near_hi = std::min(n - 1, static_cast<int>(std::floor((anchor_freq_ + reach) / df_)) - first_);
    if (near_hi >= near_lo) near_share = std::exp(-(kJumpRate + kStopRate) * dt);
  }
  const double anywhere = (p_jump_ * present + (1.0 - near_share) * p_start_ * post_absent_) / n;
  const double near =
      near_hi >= near_lo ? near_share * p_start_ * post_absent_ / (near_hi - near_lo + 1) : 0.0;
  // loglik_ is free here: write the prior into it, then into post_.
  for (int i = 0; i < n; ++i)
    loglik_[static_cast<std::size_t>(i)] =
        stay * (kSteadyShare * box(i - shift, gate_steady_) + kSlewShare * box(i - shift, gate_slew_) +
                (1.0 - kSteadyShare - kSlewShare) * box(i, gate_shift_)) +
        anywhere + (i >= near_lo && i <= near_hi ? near : 0.0);
  post_absent_ = p_stop_ * present + (1.0 - p_start_) * post_absent_;
  std::copy(loglik_.begin(), loglik_.end(), post_.begin());
}

bool TrackModel::update(double hidden) noexcept {
  hidden = std::clamp(hidden, 0.0, 1.0);
  // Logs in the window's terms (the hop's ratio over the temper), less the largest ratio `top`; a window
  // that says nothing has ratio 1 (log 0).
  const double top = std::max(0.0, *std::max_element(loglik_.begin(), loglik_.end())) / temper_;
  const double log_shown = std::log1p(-hidden);
  const double log_blank = (hidden > 0.0 ? std::log(hidden) : -INFINITY) - top;
  double total = post_absent_ * std::exp(-temper_ * top);
  for (std::size_t i = 0; i < post_.size(); ++i) {
    const double a = log_shown + loglik_[i] / temper_ - top;
    const double m = std::max(a, log_blank);
    const double log_window = m + std::log1p(std::exp(std::min(a, log_blank) - m));
    post_[i] *= std::exp(temper_ * log_window);
    total += post_[i];
  }
  if (!(total > 0.0) || !std::isfinite(total)) {
    reset();
    return false;
  }
  post_absent_ *= std::exp(-temper_ * top) / total;
  for (double& p : post_)
    p /= total;
  return true;
}

int TrackModel::mode_bin() const noexcept {
  return static_cast<int>(std::max_element(post_.begin(), post_.end()) - post_.begin()) + first_;
}

double TrackModel::mass_near(double f) const noexcept {
  if (!std::isfinite(f)) return 0.0;
  double mass = 0.0;
  const double reach = std::max(kRightFraction * f, lobe_ * df_);
  const int lo = std::max(first_, static_cast<int>(std::ceil((f - reach) / df_)));
  const int hi = std::min(last_, static_cast<int>(std::floor((f + reach) / df_)));
  for (int k = lo; k <= hi; ++k)
    mass += post_[static_cast<std::size_t>(k - first_)];
  return std::clamp(mass, 0.0, 1.0);
}

double TrackModel::predicted() const noexcept {
  return std::isfinite(last_freq_) ? last_freq_ + drift_hz_per_s_ * hop_s_ : kNaN;
}

void TrackModel::observe(double f, double right, bool tracked) noexcept {
  if (tracked) {
    anchor_freq_ = f;
    anchor_age_ = 0;
  } else {
    ++anchor_age_;
  }
  // The track's drift, from consecutive confident estimates that continue each other.
  const bool confident = right >= kConfident;
  if (confident && std::isfinite(last_freq_) && std::abs(f - last_freq_) <= max_slew_ * hop_s_ + 2.0 * df_)
    drift_hz_per_s_ = kDriftMemory * drift_hz_per_s_ + (1.0 - kDriftMemory) * (f - last_freq_) / hop_s_;
  else
    drift_hz_per_s_ *= kDriftMemory;
  last_freq_ = confident ? f : kNaN;
}

}  // namespace gearpulse
