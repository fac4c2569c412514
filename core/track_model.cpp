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
// The line's rate of change is a state: layers of rates from -max slew to +max slew, this far apart
// (Hz/s), at most kMaxRateLayers either side of 0. A continuing line moves at its layer's rate within a
// steady gate (cruise wobble, a rate between layers: a few Hz/s), unless its rate changes, within the slew
// of an accelerating engine (a ramp starts or ends) or a gear shift, about as often each.
constexpr double kSteadyHzPerS = 5.0;
constexpr double kRateStepHzPerS = 10.0;
constexpr int kMaxRateLayers = 8;
// An engine's rate of change holds for about a second (a gear's ramp lasts seconds, a shift a few tenths,
// a cruise or engine braking many): the rate changes at 1 / kRateMemoryS per second, half of the changes
// within the slew gate and half within the shift gate. Chosen on the generated scenes' tuning set (0.5,
// 0.7, 1 and 2 s; see docs/algorithms/tracker-experiments.md).
constexpr double kRateMemoryS = 0.7;
constexpr double kShiftOfChange = 0.5;
// Memory (per hop) of the track's drift, from which the next hop's line is predicted (the prior of the
// sub-bin estimate).
constexpr double kDriftMemory = 0.7;
// An estimate is right within 5 % of the engine's fundamental; a confident one has 0.8 of the posterior
// there (the tracker's "tracked").
constexpr double kRightFraction = 0.05;
constexpr double kConfident = 0.8;
// A line that rises is an engine under power, and a gear shift from it is an upshift: the revs fall by the
// gear step while the clutch is out and the new gear takes them; they do not rise. The shift gate of the
// rising layers therefore reaches below the line only. A steady line's shift may go either way (an upshift
// at a cruise, a kick-down), and a falling line's too (a downshift's blip, the revs falling to idle).
// Where an upshift leads: a car gearbox's ratio steps lower the revs to about 0.55 (first to second gear)
// to 0.85 (the top gears) of where they were; the lower edge keeps half the line (its half order, within
// 5 %) out. The engine found again after the track lost it is, with this share of the probability that it
// is near the latest tracked estimate, where an upshift from that estimate leads, and with the rest within
// the slew's reach of it, as likely the one as the other.
constexpr double kUpshiftLow = 0.55;
constexpr double kUpshiftHigh = 0.85;
constexpr double kUpshiftShare = 0.5;

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
  const double dt = hop_s_;
  const int side = std::min(kMaxRateLayers, static_cast<int>(std::ceil(max_slew_ / kRateStepHzPerS - 1e-9)));
  layers_ = 2 * side + 1;
  rate_bins_.assign(static_cast<std::size_t>(layers_), 0.0);
  for (int j = 0; j < layers_; ++j)
    rate_bins_[static_cast<std::size_t>(j)] = side > 0 ? max_slew_ * (j - side) / side * dt / df_ : 0.0;
  post_.assign(states * static_cast<std::size_t>(layers_), 0.0);
  next_.assign(post_.size(), 0.0);
  marginal_.assign(states, 0.0);
  loglik_.assign(states, 0.0);
  moved_.assign(states, 0.0);
  factor_.assign(states, 0.0);
  factor_overrun_.assign(states, 0.0);
  overrun_excess_.assign(states, 0.0);
  factor_power_.assign(states, 0.0);
  factor_upshift_.assign(states, 0.0);
  power_excess_.assign(states, 0.0);
  power_from_ = layers_;
  for (int j = layers_ - 1;
       j >= 0 && rate_bins_[static_cast<std::size_t>(j)] * df_ / dt >= kPowerHzPerS - 1e-9; --j)
    power_from_ = j;
  overrun_layers_ = 0;  // the layers falling at kOverrunHzPerS or faster: the first ones
  for (int j = 0; j < layers_; ++j)
    if (rate_bins_[static_cast<std::size_t>(j)] * df_ / dt <= -kOverrunHzPerS + 1e-9) overrun_layers_ = j + 1;
  cumsum_.assign(states + 1, 0.0);
  rising_.assign(states, 0.0);
  rising_cumsum_.assign(states + 1, 0.0);
  rise_from_ = layers_;  // the layers with a positive rate: the last ones
  for (int j = layers_ - 1; j >= 0 && rate_bins_[static_cast<std::size_t>(j)] > 0.0; --j)
    rise_from_ = j;
  gate_steady_ = static_cast<int>(std::ceil((kSteadyHzPerS * dt) / df_)) + 1;
  gate_slew_ = static_cast<int>(std::ceil((max_slew_ * dt) / df_)) + 2;
  gate_shift_ = static_cast<int>(std::ceil((std::max(max_slew_, config.shift_slew_hz_per_s) * dt) / df_)) + 2;
  const double change = 1.0 - std::exp(-dt / kRateMemoryS);
  keep_ = 1.0 - change;
  shift_share_ = kShiftOfChange * change;
  slew_share_ = change - shift_share_;
  p_stop_ = 1.0 - std::exp(-kStopRate * dt);
  p_start_ = 1.0 - std::exp(-kStartRate * dt);
  p_jump_ = 1.0 - std::exp(-kJumpRate * dt);
  reset();
}

void TrackModel::reset() noexcept {
  post_absent_ = 0.5;
  std::fill(post_.begin(), post_.end(), 0.5 / static_cast<double>(post_.size()));
  std::fill(marginal_.begin(), marginal_.end(), 0.5 / static_cast<double>(marginal_.size()));
  drift_hz_per_s_ = 0.0;
  last_freq_ = kNaN;
  anchor_freq_ = kNaN;
  anchor_age_ = 0;
  up_hi_ = -1;
}

// Prior of this hop from the previous posterior: a continuing line moves by its layer's rate within the
// steady gate, or within a slew or shift gate that redraws its rate (box kernels by prefix sums); the
// engine may stop, start, or be found anywhere.
void TrackModel::predict() noexcept {
  const auto n = static_cast<int>(marginal_.size());
  const auto un = static_cast<std::size_t>(n);
  // Sum of the sequence behind cumsum_ over [c - g, c + g] (clipped to the states), and its mean over a box
  // of half-width g centred at c + a for a fraction a in [0, 1).
  const auto sum = [&](int c, int g) {
    const int lo = std::max(0, c - g), hi = std::min(n - 1, c + g);
    return lo > hi ? 0.0 : cumsum_[static_cast<std::size_t>(hi) + 1] - cumsum_[static_cast<std::size_t>(lo)];
  };
  const auto box = [&](int c, double a, int g) {
    return ((1.0 - a) * sum(c, g) + (a > 0.0 ? a * sum(c + 1, g) : 0.0)) / (2.0 * g + 1.0);
  };
  double present = 0.0;
  for (const double p : marginal_)
    present += p;
  const double stay = 1.0 - p_stop_ - p_jump_;
  // The engine found again after the track lost it (a window smeared by a shift, a few drowned hops) is
  // where the latest tracked estimate could have ramped to since, at the slew, unless it stopped or was
  // found elsewhere meanwhile (the stop and jump rates). Without this a line found again after a lost hop
  // was as likely anywhere, and a loud 2nd harmonic there took the track for a hop at twice the engine.
  // Unless it lies beyond the states, half of that is where an upshift from the estimate leads.
  double near_share = 0.0;
  int near_lo = 0, near_hi = -1, up_lo = 0, up_hi = -1;
  if (std::isfinite(anchor_freq_)) {
    const double dt = (anchor_age_ + 1) * hop_s_;
    const double reach = max_slew_ * dt + std::max(kRightFraction * anchor_freq_, lobe_ * df_);
    near_lo = std::max(0, static_cast<int>(std::ceil((anchor_freq_ - reach) / df_)) - first_);
    near_hi = std::min(n - 1, static_cast<int>(std::floor((anchor_freq_ + reach) / df_)) - first_);
    up_lo = std::max(0, static_cast<int>(std::ceil(kUpshiftLow * anchor_freq_ / df_)) - first_);
    up_hi = std::min(n - 1, static_cast<int>(std::floor(kUpshiftHigh * anchor_freq_ / df_)) - first_);
    if (near_hi >= near_lo) near_share = std::exp(-(kJumpRate + kStopRate) * dt);
  }
  up_lo_ = up_lo;
  up_hi_ = up_hi;
  const double anywhere = (p_jump_ * present + (1.0 - near_share) * p_start_ * post_absent_) / n;
  const double upshift_share = near_share > 0.0 && up_hi >= up_lo ? kUpshiftShare : 0.0;
  const double found = near_share * p_start_ * post_absent_;
  const double near = near_hi >= near_lo ? (1.0 - upshift_share) * found / (near_hi - near_lo + 1) : 0.0;
  const double upshift = upshift_share > 0.0 ? upshift_share * found / (up_hi - up_lo + 1) : 0.0;
  // Each layer keeps its rate within the steady gate; what enters the slew gate (from the line's place
  // one hop on at its rate) and the shift gate (from where it was; below it for a rising line) is spread
  // over all rates.
  std::fill(moved_.begin(), moved_.end(), 0.0);
  std::fill(rising_.begin(), rising_.end(), 0.0);
  for (int j = 0; j < layers_; ++j) {
    const double* p = post_.data() + static_cast<std::size_t>(j) * un;
    if (j >= rise_from_)
      for (std::size_t i = 0; i < un; ++i)
        rising_[i] += p[i];
    double* q = next_.data() + static_cast<std::size_t>(j) * un;
    cumsum_[0] = 0.0;
    for (std::size_t i = 0; i < un; ++i)
      cumsum_[i + 1] = cumsum_[i] + p[i];
    // This layer's line at i comes from i - r (r its bins per hop): o whole bins and a fraction a of one.
    const double back = -rate_bins_[static_cast<std::size_t>(j)];
    const double whole = std::floor(back);
    const auto o = static_cast<int>(whole);
    const double a = back - whole;
    for (int i = 0; i < n; ++i) {
      q[i] = stay * keep_ * box(i + o, a, gate_steady_);
      moved_[static_cast<std::size_t>(i)] += box(i + o, a, gate_slew_);
    }
  }
  // The shift gate: the layers that do not rise spread within it both ways (cumsum_), the rising ones
  // (rising_cumsum_) into the one side below the line, of gate_shift_ + 1 fine bins.
  cumsum_[0] = rising_cumsum_[0] = 0.0;
  for (std::size_t i = 0; i < un; ++i) {
    cumsum_[i + 1] = cumsum_[i] + (marginal_[i] - rising_[i]);
    rising_cumsum_[i + 1] = rising_cumsum_[i] + rising_[i];
  }
  const double per_layer = 1.0 / layers_;
  const double below = 1.0 / (gate_shift_ + 1.0);
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    const auto top = static_cast<std::size_t>(std::min(n - 1, i + gate_shift_)) + 1;
    const double upshift_in = below * (rising_cumsum_[top] - rising_cumsum_[ui]);
    moved_[ui] =
        per_layer *
        (stay * (slew_share_ * moved_[ui] + shift_share_ * (box(i, 0.0, gate_shift_) + upshift_in)) +
         anywhere + (i >= near_lo && i <= near_hi ? near : 0.0) + (i >= up_lo && i <= up_hi ? upshift : 0.0));
  }
  for (int j = 0; j < layers_; ++j) {
    double* q = next_.data() + static_cast<std::size_t>(j) * un;
    for (std::size_t i = 0; i < un; ++i)
      q[i] += moved_[i];
  }
  post_absent_ = p_stop_ * present + (1.0 - p_start_) * post_absent_;
  post_.swap(next_);
}

bool TrackModel::update(double hidden) noexcept {
  hidden = std::clamp(hidden, 0.0, 1.0);
  // Logs in the window's terms (the hop's ratio over the temper), less the largest ratio `top`; a window
  // that says nothing has ratio 1 (log 0). The ratio depends on the fundamental alone, and on whether the
  // line is on the overrun or under power: factor_ takes each fundamental's, which multiplies every layer
  // but the overrun's and power's, factor_overrun_ and factor_power_ theirs.
  double top = std::max(0.0, *std::max_element(loglik_.begin(), loglik_.end())) / temper_;
  if (overrun_layers_ > 0)
    for (std::size_t i = 0; i < loglik_.size(); ++i)
      top = std::max(top, (loglik_[i] + overrun_excess_[i]) / temper_);
  if (power_from_ < layers_)
    for (std::size_t i = 0; i < loglik_.size(); ++i)
      top = std::max(top, (loglik_[i] + power_excess_[i]) / temper_);
  const double log_shown = std::log1p(-hidden);
  const double log_blank = (hidden > 0.0 ? std::log(hidden) : -INFINITY) - top;
  const std::size_t n = marginal_.size();
  const auto factor = [&](double loglik) {
    const double a = log_shown + loglik / temper_ - top;
    const double m = std::max(a, log_blank);
    return std::exp(temper_ * (m + std::log1p(std::exp(std::min(a, log_blank) - m))));
  };
  for (std::size_t i = 0; i < n; ++i)
    factor_[i] = factor(loglik_[i]);
  if (overrun_layers_ > 0)
    for (std::size_t i = 0; i < n; ++i)
      factor_overrun_[i] = factor(loglik_[i] + overrun_excess_[i]);
  if (power_from_ < layers_)
    for (std::size_t i = 0; i < n; ++i)
      factor_power_[i] = factor(loglik_[i] + power_excess_[i]);
  // Where an upshift leads, a loud 2nd harmonic is read as likely as on the overrun, but a usual one keeps
  // the usual prior's odds: the better of the two ratios. A candidate at twice the new gear (1.1-1.7 times
  // the estimate) lies above the range, and one at half the old line (0.5) below it.
  const bool upshift = overrun_layers_ > 0 && up_hi_ >= up_lo_;
  if (upshift) {
    std::copy(factor_.begin(), factor_.end(), factor_upshift_.begin());
    for (auto i = static_cast<std::size_t>(up_lo_); i <= static_cast<std::size_t>(up_hi_); ++i)
      factor_upshift_[i] = std::max(factor_[i], factor_overrun_[i]);
  }
  double total = post_absent_ * std::exp(-temper_ * top);
  std::fill(marginal_.begin(), marginal_.end(), 0.0);
  for (int j = 0; j < layers_; ++j) {
    double* p = post_.data() + static_cast<std::size_t>(j) * n;
    const double* f = j < overrun_layers_ ? factor_overrun_.data()
                      : j >= power_from_  ? factor_power_.data()
                      : upshift           ? factor_upshift_.data()
                                          : factor_.data();
    for (std::size_t i = 0; i < n; ++i) {
      p[i] *= f[i];
      marginal_[i] += p[i];
    }
  }
  for (const double m : marginal_)
    total += m;
  if (!(total > 0.0) || !std::isfinite(total)) {
    reset();
    return false;
  }
  post_absent_ *= std::exp(-temper_ * top) / total;
  const double scale = 1.0 / total;
  for (double& p : post_)
    p *= scale;
  for (double& m : marginal_)
    m *= scale;
  return true;
}

int TrackModel::mode_bin() const noexcept {
  return static_cast<int>(std::max_element(marginal_.begin(), marginal_.end()) - marginal_.begin()) + first_;
}

double TrackModel::mass_near(double f) const noexcept {
  if (!std::isfinite(f)) return 0.0;
  double mass = 0.0;
  const double reach = std::max(kRightFraction * f, lobe_ * df_);
  const int lo = std::max(first_, static_cast<int>(std::ceil((f - reach) / df_)));
  const int hi = std::min(last_, static_cast<int>(std::floor((f + reach) / df_)));
  for (int k = lo; k <= hi; ++k)
    mass += marginal_[static_cast<std::size_t>(k - first_)];
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
