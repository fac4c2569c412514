#include "tools/gearpulse/fit_summary.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include <fmt/format.h>

#include "core/log_reading.hpp"

namespace gearpulse::cli {
namespace {

// The speed at the given fraction of the sorted `speeds` (nearest rank).
double quantile(const std::vector<double>& speeds, double q) {
  const auto i = static_cast<std::size_t>(q * static_cast<double>(speeds.size() - 1) + 0.5);
  return speeds[std::min(i, speeds.size() - 1)];
}

}  // namespace

std::string fit_summary(const GearModel& model, std::span<const Sample> samples, bool rpm_logs) {
  if (model.gears.empty()) return {};
  double fastest = 0.0;
  // Each moving sample in the gear whose window (kGearWindow either side of its theta on the log scale)
  // holds its speed / frequency: shifts and clutch slip fall between the windows.
  std::vector<std::vector<double>> in_gear(model.gears.size());
  for (const Sample& s : samples) {
    if (!(s.has_speed() && s.has_freq() && s.speed > 0.0 && s.freq > 0.0)) continue;
    fastest = std::max(fastest, s.speed);
    const double log_ratio = std::log(s.speed / s.freq);
    for (std::size_t g = 0; g < model.gears.size(); ++g)
      if (std::abs(log_ratio - std::log(model.gears[g].theta)) < kGearWindow) {
        in_gear[g].push_back(s.speed);
        break;
      }
  }
  using log_reading::kKmhToMs;
  std::string text =
      fmt::format("gearpulse: {} gear{}, fitted on {} samples (the fastest at {:.0f} km/h):\n",
                  model.gears.size(), model.gears.size() == 1 ? "" : "s", model.samples, fastest / kKmhToMs);
  std::size_t rough = 0;
  for (std::size_t g = 0; g < model.gears.size(); ++g) {
    const Gear& gear = model.gears[g];
    std::vector<double>& speeds = in_gear[g];
    std::sort(speeds.begin(), speeds.end());
    std::string line = fmt::format("  gear {}: theta {:.4f} (m/s)/Hz +- {:.2g} %", g + 1, gear.theta,
                                   100.0 * gear.std_error / gear.theta);
    // theta (m/s)/Hz x 1000 rpm / 60 (Hz), in km/h: 60 theta km/h per 1000 rpm.
    if (rpm_logs)
      line += fmt::format(", {:.1f} km/h per 1000 rpm",
                          gear.theta * 1000.0 / log_reading::kSecondsPerMinute / kKmhToMs);
    // The fit's own count: the gear's weight (eq. (6)) of the samples it read.
    line += fmt::format("; about {:.0f} samples in gear", gear.weight * static_cast<double>(model.samples));
    if (!speeds.empty())
      line += fmt::format(", mostly at {:.0f}-{:.0f} km/h", quantile(speeds, 0.05) / kKmhToMs,
                          quantile(speeds, 0.95) / kKmhToMs);
    if (gear.std_error > kRoughGear * gear.theta) {
      ++rough;
      line += " (rough)";
    }
    text += line + '\n';
  }
  // A manual car moves off in first gear, which carries it at idle at kFirstGearIdleSpeed at most; a
  // motorcycle's (2.9-3.9 m/s, core/auto_ladder_completion.cpp) or a tall one may carry it faster
  // (docs/cold-start.md): the line says what would tell, not that first gear is missing.
  if (const auto idle = model.extra.find("idle"); idle != model.extra.end() && idle->is_object()) {
    const double idle_freq = idle->value("freq", 0.0);
    const double at_idle = model.gears.front().theta * idle_freq;
    if (idle_freq > 0.0 && at_idle > kFirstGearIdleSpeed)
      text += fmt::format(
          "  gear 1 carries the car at {:.0f} km/h at idle, more than a car's first gear does (a "
          "motorcycle's or a tall one may): if there is a lower gear, log some starts from rest\n",
          at_idle / kKmhToMs);
  }
  if (rough > 0)
    text += fmt::format(
        "  a rough gear's scale is known to worse than {:.2g} %: log more driving in that gear and fit all "
        "the logs again\n",
        100.0 * kRoughGear);
  text += fmt::format(
      "  if the car has more than {} forward gears, log a drive that holds the others for a while and fit "
      "all the logs again\n",
      model.gears.size());
  return text;
}

}  // namespace gearpulse::cli
