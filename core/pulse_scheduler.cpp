#include "core/pulse_scheduler.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace gearpulse {
namespace {

constexpr double kNsPerS = 1e9;
// The pulses owed are bounded by this long at max_freq_hz: far more than a thread woken late owes (the
// pulse thread counts an edge 1 ms behind as late), and little enough that a backlog paid out after a stop
// moves the navigator's car for at most half a second.
constexpr double kMaxOwedS = 0.5;

[[noreturn]] void bad(const std::string& field, const std::string& why) {
  throw std::invalid_argument("pulse config: " + field + " " + why);
}

}  // namespace

void validate(const PulseConfig& c) {
  if (!(std::isfinite(c.pulses_per_km) && c.pulses_per_km > 0)) bad("pulses_per_km", "must be positive");
  if (!(std::isfinite(c.min_freq_hz) && c.min_freq_hz > 0)) bad("min_freq_hz", "must be positive");
  if (!(std::isfinite(c.max_freq_hz) && c.max_freq_hz > c.min_freq_hz))
    bad("max_freq_hz", "must be finite and above min_freq_hz");
  if (!(std::isfinite(c.pulse_width_s) && c.pulse_width_s >= 0)) bad("pulse_width_s", "must be >= 0");
  if (c.pulse_width_s > 0 && c.pulse_width_s * c.max_freq_hz >= 1.0)
    bad("pulse_width_s", "must be shorter than one period at max_freq_hz");
  if (c.pulse_width_s == 0 && !(c.duty > 0 && c.duty < 1)) bad("duty", "must lie in (0, 1)");
}

PulseScheduler::PulseScheduler(const PulseConfig& config, std::int64_t t0_ns)
    : config_(config), min_spacing_ns_(0), t_(t0_ns) {
  validate(config_);
  min_spacing_ns_ = kNsPerS / config_.max_freq_hz;
  max_owed_ = 1.0 + kMaxOwedS * config_.max_freq_hz;
  // The shortest low time the train ever has (at max frequency); a rise that is late never comes sooner
  // than this after the previous fall, so a counter on the line sees every pulse.
  min_low_ns_ = config_.pulse_width_s > 0 ? min_spacing_ns_ - config_.pulse_width_s * kNsPerS
                                          : (1.0 - config_.duty) * min_spacing_ns_;
}

void PulseScheduler::advance_to(std::int64_t t_ns) noexcept {
  if (t_ns <= t_) return;
  owed_ += freq_ * static_cast<double>(t_ns - t_) / kNsPerS;
  t_ = t_ns;
  if (owed_ > max_owed_) {
    discarded_ += owed_ - max_owed_;
    owed_ = max_owed_;
  }
}

void PulseScheduler::set_speed(std::int64_t t_ns, double speed_mps) noexcept {
  advance_to(t_ns);
  speed_ = speed_mps > 0 && std::isfinite(speed_mps) ? speed_mps : 0.0;
  double f = speed_ * config_.pulses_per_km / 1000.0;
  if (f < config_.min_freq_hz) f = 0.0;
  freq_ = std::min(f, config_.max_freq_hz);
  // A pulse high for the duty of a slower frequency falls when one at the new frequency would (not before
  // now): a slow pulse is high for up to duty / min_freq_hz, and held through a speed-up it let the count
  // fall behind the distance by the pulses owed meanwhile, caught up only over the following seconds.
  if (high_ && config_.pulse_width_s == 0 && freq_ > 0.0) {
    const std::int64_t fall = last_rise_ns_ + std::llround(config_.duty / freq_ * kNsPerS);
    fall_ns_ = std::min(fall_ns_, std::max(fall, t_));
  }
}

std::int64_t PulseScheduler::next_rise_ns() const noexcept {
  double rise;
  if (owed_ >= 1.0) {
    rise = static_cast<double>(t_);  // late: due now
  } else if (freq_ > 0.0) {
    rise = static_cast<double>(t_) + std::ceil((1.0 - owed_) / freq_ * kNsPerS);
  } else {
    return PulseEdge::kNever;
  }
  rise = std::max({rise, static_cast<double>(last_rise_ns_) + min_spacing_ns_,
                   static_cast<double>(last_fall_ns_) + min_low_ns_});
  return static_cast<std::int64_t>(std::ceil(rise));
}

PulseEdge PulseScheduler::next_edge() const noexcept {
  if (high_) return {fall_ns_, EdgeKind::kFall};
  const std::int64_t rise = next_rise_ns();
  if (rise == PulseEdge::kNever) return {};
  return {rise, EdgeKind::kRise};
}

PulseEdge PulseScheduler::pop_due(std::int64_t t_ns) noexcept {
  return commit(t_ns, PulseEdge::kNever);
}

PulseEdge PulseScheduler::emit_due(std::int64_t now_ns) noexcept {
  return commit(now_ns, now_ns);
}

PulseEdge PulseScheduler::commit(std::int64_t t_ns, std::int64_t made_ns) noexcept {
  const PulseEdge e = next_edge();
  if (e.kind == EdgeKind::kNone || e.t_ns > t_ns) return {};
  const std::int64_t made = std::max(e.t_ns, made_ns == PulseEdge::kNever ? e.t_ns : made_ns);
  if (e.kind == EdgeKind::kFall) {
    high_ = false;
    last_fall_ns_ = made;
    fall_ns_ = PulseEdge::kNever;
    return e;
  }
  advance_to(e.t_ns);
  owed_ -= 1.0;
  ++pulses_;
  high_ = true;
  last_rise_ns_ = made;
  // The width is fixed at the rise: a speed change while high moves later pulses, never this fall.
  const double width_s =
      config_.pulse_width_s > 0
          ? config_.pulse_width_s
          : config_.duty / std::max(freq_ > 0 ? freq_ : config_.max_freq_hz, config_.min_freq_hz);
  fall_ns_ = made + static_cast<std::int64_t>(std::llround(width_s * kNsPerS));
  return e;
}

double PulseScheduler::phase_pulses(std::int64_t t_ns) const noexcept {
  const double ahead = t_ns > t_ ? freq_ * static_cast<double>(t_ns - t_) / kNsPerS : 0.0;
  return static_cast<double>(pulses_) + owed_ + ahead;
}

}  // namespace gearpulse
