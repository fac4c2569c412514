#include "core/seen_gears.hpp"

#include <algorithm>
#include <cmath>

#include "core/estimator.hpp"

namespace gearpulse {
namespace {

constexpr double kMovingSpeed = 1.0;  // m/s: fixes above this tell a gear's ratio (the fit's rule)
constexpr double kMaxFixGap = 6.0;    // s: two fixes further apart are not neighbours in time
// The most a fix's lateness may move a sighting's ratio (the floor of a reading's noise): a fix `lag` late,
// read while the car gains or loses speed at a share g a second, gives a ratio off by lag x g, so the speed
// may change between two fixes of a sighting by at most this share over the lag a second (2 % a second at
// 0.5 s late, 1.1 % at 0.9 s). Read during a launch with no such bound, a gear's ratio came out 7-9 % low
// (GPS 0.5 s late), a gear of its own beside the true one.
constexpr double kLagBias = 0.01;
// s: the least lateness a sighting is judged at. The lag measured is a fix's mean lateness; each fix's own
// timing against the revs scatters about it by up to half a second (a logger polls speed and rpm each at its
// own instant within its round, a receiver reports within its period), so a fix said to be current is no
// licence for a faster change (with no floor, OBD rows at 2 s erred 3.45 / 42.90 -> 3.90 / 44.88 %).
constexpr double kLeastLag = 0.5;
// Floor on the spread of a gear's ratios for its standard error: the tracker's jitter and driveline slip
// leave about 1 % on every reading.
constexpr double kMinRatioSd = 0.01;

// Whether log ratio r lies within a gearbox step (a factor of 1.06) of one of the thetas.
bool near_any(double r, std::span<const double> thetas) noexcept {
  return std::any_of(thetas.begin(), thetas.end(), [&](double theta) {
    return theta > 0.0 && std::abs(r - std::log(theta)) < 2.0 * kGearWindow;
  });
}

}  // namespace

bool SeenGears::is_seen(const Sighting& s) const noexcept {
  return std::isfinite(min_fixes_) && min_fixes_ > 0.0 && s.longest_run >= min_fixes_;
}

bool SeenGears::observe(double t, double speed, double freq, double idle_ceiling,
                        std::span<const double> model_thetas, double lag, bool lugged) noexcept {
  bool changed = false;
  for (Sighting& s : slots_) {
    if (s.count > 0.0 && t - s.last_t > kForgetTime) {
      changed = changed || is_seen(s);
      s = {};
    }
  }
  if (!std::isfinite(speed) || !std::isfinite(freq) || speed <= kMovingSpeed || freq <= 0.0 ||
      freq <= idle_ceiling) {
    have_prev_ = false;
    run_slot_ = -1;
    return changed;
  }
  const double r = std::log(speed / freq);
  const bool steady =
      have_prev_ && t - prev_t_ <= kMaxFixGap && t > prev_t_ && steady_ratios_agree(r, prev_ratio_, speed) &&
      std::abs(std::log(speed / prev_speed_)) * std::max(lag, kLeastLag) < kLagBias * (t - prev_t_);
  have_prev_ = true;
  prev_t_ = t;
  prev_ratio_ = r;
  prev_speed_ = speed;
  if (!steady || near_any(r, model_thetas)) run_slot_ = -1;
  if (!steady) return changed;
  steady_fixes_ += 1.0;
  if (near_any(r, model_thetas)) return changed;
  // The sighting of the nearest gear within half a gear window, else a new one in a free slot (or in place
  // of the one sighted least, then longest ago, that is not yet seen).
  Sighting* slot = nullptr;
  for (Sighting& s : slots_)
    if (s.count > 0.0 && std::abs(r - s.mean) < kGearWindow &&
        (!slot || std::abs(r - s.mean) < std::abs(r - slot->mean)))
      slot = &s;
  if (slot == nullptr) {
    for (Sighting& s : slots_) {
      if (is_seen(s)) continue;
      if (!slot || s.count < slot->count || (s.count == slot->count && s.last_t < slot->last_t)) slot = &s;
    }
    if (slot == nullptr) return changed;
    *slot = {};
    run_slot_ = -1;
  }
  const bool was_seen = is_seen(*slot);
  const bool was_creep = slot->above <= 0.0;
  const int index = static_cast<int>(slot - slots_.data());
  run_length_ = index == run_slot_ ? run_length_ + 1.0 : 1.0;
  run_slot_ = index;
  slot->longest_run = std::max(slot->longest_run, run_length_);
  slot->count += 1.0;
  if (!lugged) slot->above += 1.0;
  const double d = r - slot->mean;
  slot->mean += d / slot->count;
  slot->m2 += d * (r - slot->mean);
  slot->last_t = t;
  // A seen gear sighted for the first time at revs not lugged is a gear, no longer a possible creep.
  return changed || (!was_seen && is_seen(*slot)) || (was_seen && was_creep && !lugged);
}

bool SeenGears::forget_learned(std::span<const double> model_thetas) noexcept {
  bool changed = false;
  for (Sighting& s : slots_) {
    if (s.count > 0.0 && near_any(s.mean, model_thetas)) {
      changed = changed || is_seen(s);
      s = {};
      run_slot_ = -1;
    }
  }
  return changed;
}

int SeenGears::seen(std::array<Gear, kCapacity>& out) const noexcept {
  int n = 0;
  for (const Sighting& s : slots_) {
    if (!is_seen(s)) continue;
    // Two gears seen a gearbox step apart or less are one: the one sighted more stands for it.
    bool shadowed = false;
    for (const Sighting& o : slots_)
      shadowed =
          shadowed || (&o != &s && is_seen(o) && (o.count > s.count || (o.count == s.count && &o < &s)) &&
                       std::abs(o.mean - s.mean) < 2.0 * kGearWindow);
    if (shadowed) continue;
    const double sd = std::max(std::sqrt(s.m2 / std::max(s.count - 1.0, 1.0)), kMinRatioSd);
    const double theta = std::exp(s.mean);
    out[static_cast<std::size_t>(n++)] = {theta, theta * sd / std::sqrt(s.count), s.count / steady_fixes_,
                                          s.above <= 0.0};
  }
  return n;
}

void SeenGears::clear() noexcept {
  slots_.fill({});
  have_prev_ = false;
  steady_fixes_ = 0.0;
  run_slot_ = -1;
}

}  // namespace gearpulse
