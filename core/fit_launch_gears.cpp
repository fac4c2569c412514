// The launches from rest in a fit's log, counted as the synthesis counts those it sees under GPS
// (LaunchGears, core/launch_gears.hpp): how many upshifts each makes before the car drives the ladder's
// lowest gear. Estimator::fit records the counts (extra.launch_gears) for the synthesis, whose own count
// starts from a drive's first launch: a drive that meets an outage in a jam before its first launch was
// counted had only the idle to tell whether its ladder's lowest gear is first.
#include <cmath>
#include <cstddef>
#include <limits>
#include <optional>

#include "core/estimator_internal.hpp"
#include "core/launch_gears.hpp"

namespace gearpulse::detail {
namespace {

// A log whose revs are read further apart on average than a launch holds first gear passes it unread.
constexpr double kFirstGearHeld = LaunchGears::kFirstGearHeld;
constexpr double kIdleSds = LaunchGears::kIdleSds;
// s: rows further apart than the slowest polling app reads (a phone OBD app's round of 2-6 s) are a gap in
// the log (GPS lost, logging paused): a launch across it is not counted.
constexpr double kMaxRowGap = 6.0;

// The gear of `model` whose theta lies nearest `ratio` in log, if nearer it than a gear `step` (log) below
// the lowest would be.
std::optional<std::size_t> nearest_gear(const GearModel& model, double ratio, double step) {
  const double r = std::log(ratio);
  std::size_t best = 0;
  for (std::size_t i = 1; i < model.gears.size(); ++i)
    if (std::abs(r - std::log(model.gears[i].theta)) < std::abs(r - std::log(model.gears[best].theta)))
      best = i;
  if (best == 0 && r < std::log(model.gears[0].theta) - 0.5 * step) return std::nullopt;
  return best;
}

}  // namespace

std::optional<LaunchCounts> estimate_launch_gears(const MixtureData& data, const GearModel& model,
                                                  const IdleEstimate& idle) {
  const std::size_t n = data.size();
  if (data.t.size() != n || model.gears.size() < 2 || n < 2) return std::nullopt;
  // The log's reading interval of the revs: a row reads them where they changed, or where the speed did
  // not either (a logger's row for a new speed repeats the revs of its last poll).
  double read_sum = 0.0, last_read = std::numeric_limits<double>::quiet_NaN();
  std::size_t reads = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (k > 0 && data.s[k] == data.s[k - 1] && data.v[k] != data.v[k - 1]) continue;
    if (std::isfinite(last_read) && data.t[k] > last_read && data.t[k] - last_read <= kMaxRowGap)
      read_sum += data.t[k] - last_read, ++reads;
    last_read = data.t[k];
  }
  if (reads == 0 || read_sum / static_cast<double>(reads) > kFirstGearHeld) return std::nullopt;

  const double base = model.gears[0].theta;
  const double step = std::log(model.gears[1].theta / base);
  const double ceiling = idle.freq + kIdleSds * idle_spread(idle.freq, idle.sd);
  LaunchGears launches;
  std::optional<std::size_t> line_before;
  for (std::size_t k = 0; k < n; ++k) {
    if (k > 0 && !(data.t[k] > data.t[k - 1] && data.t[k] - data.t[k - 1] <= kMaxRowGap)) launches.abort();
    launches.observe_revs(data.s[k], step, ceiling);
    // The car drives a gear where two rows in a row lie nearer its theta than any other's, or than that of a
    // gear one base step below the base (a progressive gearbox's steps below it are no smaller): the
    // filter's confident belief under GPS, which a row crossing a line in a shift or a slipping clutch does
    // not give. (gear_on_line's floor of 0.8 m/s takes first gear's rows at a walking pace for the base's.)
    const auto line = data.v[k] > kMovingSpeed && data.s[k] > 0.0
                          ? nearest_gear(model, data.v[k] / data.s[k], step)
                          : std::nullopt;
    const int above = line && line == line_before ? static_cast<int>(*line) : -1;
    line_before = line;
    launches.observe_fix(data.t[k], data.v[k] < kStandingSpeed, base, above);
  }
  LaunchCounts out;
  out.base_theta = base;
  for (int k = 0; k <= LaunchGears::kMaxBelow; ++k) {
    out.counts[static_cast<std::size_t>(k)] = launches.launches(k);
    out.launches += launches.launches(k);
  }
  if (out.launches <= 0.0) return std::nullopt;
  return out;
}

}  // namespace gearpulse::detail
