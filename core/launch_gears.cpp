#include "core/launch_gears.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/estimator.hpp"

namespace gearpulse {
namespace {

// s after moving off within which the filter holds a measured gear: a launch through first to third takes
// 5-10 s; one that lasts longer is a crawl in a jam, not a launch.
constexpr double kMaxLaunchTime = 20.0;
// An upshift lowers the revs by a gearbox step, no smaller than the base's own to the gear above it: a
// fall of this share of that step (at least two gear windows) is one.
constexpr double kShareOfStep = 0.75;

}  // namespace

void LaunchGears::observe_revs(double freq, double step, double idle_ceiling) noexcept {
  if (state_ == State::kIdle || !std::isfinite(freq) || freq <= 0.0) return;
  const double lf = std::log(freq);
  if (falling_) {
    // The upshift ends where the revs climb again in the new gear, by more than their jitter. A gear held
    // for a moment only is passed with no climb: the fall then spans its step too, and counts once for
    // each whole step of the base's from the peak to the reading that ends it (the steps below the base
    // are no smaller). A fall into the idle band is a declutch whose depth tells nothing of the gears
    // passed: it counts once.
    trough_ = std::min(trough_, lf);
    if (lf > trough_ + kGearWindow) {
      if (step > 0.0 && trough_ > std::log(idle_ceiling)) {
        const double steps = std::min(std::floor((peak_ - lf) / step), static_cast<double>(kMaxBelow + 1));
        upshifts_ += std::max(0, static_cast<int>(steps) - 1);
      }
      falling_ = false, peak_ = lf;
    }
    return;
  }
  peak_ = std::max(peak_, lf);
  if (state_ == State::kLaunch && lf < peak_ - std::max(kShareOfStep * step, 2.0 * kGearWindow)) {
    ++upshifts_;
    falling_ = true;
    trough_ = lf;
  }
}

void LaunchGears::observe_fix(double t, bool standing, double base_theta, int above) noexcept {
  if (standing) {
    // Revs before the car moves (a blip, the idle settling) are no shift.
    state_ = State::kStanding;
    upshifts_ = 0;
    falling_ = false;
    peak_ = -std::numeric_limits<double>::infinity();
    return;
  }
  if (state_ == State::kStanding) state_ = State::kLaunch, moved_ = t;
  if (state_ != State::kLaunch) return;
  if (t - moved_ > kMaxLaunchTime) state_ = State::kIdle;  // a crawl, not a launch
  if (above < 0 || state_ != State::kLaunch) return;
  state_ = State::kIdle;
  const int below = upshifts_ - above;
  if (below < 0 || !(base_theta > 0.0)) return;  // a shift missed: nothing to count
  if (!same_base(base_theta)) {
    counts_.fill(0.0);  // another gear is the base: the counts were of the gears below the old one
    base_theta_ = base_theta;
  }
  counts_[static_cast<std::size_t>(std::min(below, kMaxBelow))] += 1.0;
}

void LaunchGears::seed(double base_theta, const std::array<double, kMaxBelow + 1>& counts) noexcept {
  fit_base_ = base_theta > 0.0 ? base_theta : 0.0;
  fit_counts_ = counts;
}

// Whether `base_theta` is the base the counts belong to: within two gear windows of it.
bool LaunchGears::same_base(double base_theta) const noexcept {
  return base_theta_ > 0.0 && base_theta > 0.0 &&
         std::abs(std::log(base_theta / base_theta_)) < 2.0 * kGearWindow;
}

namespace {

// The most probable count of gears below the base given `counts` of launches per count, the prior centred
// on `centre` (launch_gears.hpp).
int most_probable(const std::array<double, LaunchGears::kMaxBelow + 1>& counts, int centre,
                  double off_share) noexcept {
  const double off = std::clamp(off_share, 1e-6, 0.5);
  const double log_on = std::log(1.0 - off), log_off = std::log(off / LaunchGears::kMaxBelow);
  double total = 0.0;
  for (double c : counts)
    total += c;
  int best = centre;
  double best_score = -std::numeric_limits<double>::infinity();
  for (int k = 0; k <= LaunchGears::kMaxBelow; ++k) {
    const double on = counts[static_cast<std::size_t>(k)];
    const double score = std::abs(k - centre) * std::log(off) + on * log_on + (total - on) * log_off;
    if (score > best_score) best = k, best_score = score;
  }
  return best;
}

}  // namespace

int LaunchGears::gears_below(double base_theta, int idle_count, double off_share) const noexcept {
  if (idle_count >= kMaxBelow) return idle_count;
  // The fit's launches may ask for more gears than the idle does, never fewer: a count read at a log's
  // rows misses a fall (a first gear passed between two readings) more often than it reads one that is
  // none, so its zeros are weak evidence, and a drive's own launches still decide against it.
  int centre = idle_count;
  if (fit_base_ > 0.0 && std::abs(std::log(base_theta / fit_base_)) < 2.0 * kGearWindow)
    centre = std::max(centre, most_probable(fit_counts_, idle_count, off_share));
  if (!same_base(base_theta)) return centre;
  return most_probable(counts_, centre, off_share);
}

}  // namespace gearpulse
