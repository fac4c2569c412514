// Auto fit, the chosen ladder completed: one gear for a model still learning where no ladder passes
// (single_cluster), first gear restored where BIC dropped it (with_first_gear: a ladder that starts too
// fast at idle or spans too little for a gearbox), and the lower gears of a larger plausible ladder
// recorded for the synthesis (record_lower_gears).
#include <algorithm>
#include <cmath>
#include <span>

#include "core/auto_estimator_internal.hpp"
#include "core/estimator.hpp"

namespace gearpulse::detail {
namespace {

struct Window {
  std::size_t begin = 0;
  std::size_t count = 0;
};

// The window of width 2 x kGearWindow over sorted log ratios that holds the most of them.
Window densest_window(std::span<const double> sorted) {
  Window best;
  for (std::size_t b = 0, e = 0; b < sorted.size(); ++b) {
    while (e < sorted.size() && sorted[e] <= sorted[b] + 2.0 * kGearWindow)
      ++e;
    if (e - b > best.count) best = {b, e - b};
  }
  return best;
}

}  // namespace

// One gear, for a model still learning: the densest window of steady ratios, fitted alone, if it holds at
// least half of the steady moving pairs and fewer steady pairs than a fit needs (kMinMovingSamples) lie
// outside it (more steady driving elsewhere is a gear the ladder should show, or a continuum, as from a
// CVT below the ratio it holds at cruise), and it passes the physical checks a ladder's gears pass. An
// empty candidate otherwise.
Candidate single_cluster(const MixtureData& work, const std::vector<double>& steady, const LadderJudge& judge,
                         double vmax) {
  std::vector<double> sorted = steady;
  std::sort(sorted.begin(), sorted.end());
  const Window densest = densest_window(sorted);
  if (densest.count == 0 || 2 * densest.count < sorted.size() ||
      sorted.size() - densest.count >= kMinMovingSamples)
    return {};
  const double centre = sorted[densest.begin + densest.count / 2];
  MixtureParams p = initial_params(work, {centre}, vmax);
  const double ll = run_em(work, p, kEmIterations, 1e-6);
  if (p.gears() != 1 || judge.check(p).offender >= 0) return {};
  if (std::abs(std::log(p.theta[0]) - centre) > kGearWindow) return {};  // EM left the cluster
  return {p, ll, bic_of(ll, 1, work.size())};
}

// The gears below the chosen ladder that a plausible ladder of more gears held (BIC judged their pairs too
// few to pay for them: a launch passes first gear in a second or two), as `extra.lower_gears`, ascending.
// The synthesis takes them for the gears a ladder that lacks first gear has below it, where it would
// otherwise predict them from the ladder's steps.
void record_lower_gears(const std::vector<double>& largest, GearModel& fitted) {
  if (fitted.gears.empty()) return;
  const double below = fitted.gears.front().theta * std::exp(-2.0 * kGearWindow);
  std::vector<double> lower;
  for (const double theta : largest)
    if (theta < below) lower.push_back(theta);
  std::sort(lower.begin(), lower.end());
  if (!lower.empty()) fitted.extra["lower_gears"] = lower;
}

// The smallest spread (top gear's theta over first gear's) of a road vehicle's gearbox: a car's first gear
// launches it (13-18:1 overall) and its top gear cruises (2.5-4:1), so 2.8x at least; a motorcycle's power
// to weight lets its first gear be tall, 2.3-3.2x. A ratio of thetas, so whatever multiple of the crank the
// frequency is, and known without the idle.
constexpr double kMinSpread = 2.3;

// A manual car moves off in first gear, which carries it at the warm idle at kFirstGearIdleSpeed at most.
// A chosen ladder whose lowest gear carries it faster lacks first gear: that gear exists whatever the number
// of its pairs, and what BIC weighs (whether a gear's pairs pay for its parameters) is then no question. A
// launch passes first gear in a second or two, and where the pairs of those seconds are spread (OBD values
// polled apart while the car gains 2-3 m/s^2 spread its ratios by 20-30 %) the gear gains less than BIC
// asks. Where a plausible ladder met on the way down (every check passed: support, steps, valleys, clutch
// slip) holds the chosen ladder's gears and more below them, the lowest of which can be first gear, the
// best of those by BIC is the fit. A ladder spanning less than kMinSpread lacks its lowest gears likewise:
// where no ladder completes it by the idle (a motorcycle's first gear carries it at idle at 2.9-3.9 m/s,
// above a car's bound, and a log may have no standstill), the best plausible one spanning kMinSpread that
// holds it and more below is the fit. A ladder whose lowest gear can be first gear and that spans a gearbox
// stays as BIC chose it, and nothing is added that the checks rejected.
Candidate with_first_gear(const Candidate& best, const std::vector<Candidate>& plausible, double idle_freq) {
  const std::vector<double>& chosen_theta = best.params.theta;
  if (chosen_theta.size() < 2) return best;
  auto starts_fast = [&](const std::vector<double>& theta) {
    return idle_freq > 0.0 && theta.front() * idle_freq > kFirstGearIdleSpeed;
  };
  auto narrow = [](const std::vector<double>& theta) { return theta.back() < kMinSpread * theta.front(); };
  const double below = chosen_theta.front() * std::exp(-2.0 * kGearWindow);  // a gearbox step below
  // The best by BIC of the plausible ladders that hold the chosen one's gears and more below them and that
  // `complete` takes to reach first gear; null if none.
  auto completion = [&](auto complete) {
    const Candidate* found = nullptr;
    for (const Candidate& c : plausible) {
      const std::vector<double>& theta = c.params.theta;
      if (theta.size() <= chosen_theta.size() || !complete(theta)) continue;
      const auto lower = static_cast<std::size_t>(std::lower_bound(theta.begin(), theta.end(), below) -
                                                  theta.begin());  // gears below the chosen
      if (theta.size() - lower != chosen_theta.size()) continue;
      bool same = true;
      for (std::size_t i = 0; i < chosen_theta.size(); ++i)
        same = same && std::abs(std::log(theta[lower + i] / chosen_theta[i])) < kGearWindow;
      if (same && (found == nullptr || c.bic < found->bic)) found = &c;
    }
    return found;
  };
  const Candidate* completed = nullptr;
  if (starts_fast(chosen_theta))
    completed = completion([&](const std::vector<double>& theta) { return !starts_fast(theta); });
  if (completed == nullptr && narrow(chosen_theta))
    completed = completion([&](const std::vector<double>& theta) { return !narrow(theta); });
  return completed != nullptr ? *completed : best;
}

}  // namespace gearpulse::detail

namespace gearpulse {

std::size_t largest_gear_cluster(std::span<const double> sorted_log_ratios) {
  return detail::densest_window(sorted_log_ratios).count;
}

}  // namespace gearpulse
