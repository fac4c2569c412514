// The units of the logs' speeds: the one a column's name states, a reading written with its unit (a
// python-OBD quantity), and the one a `speed,rpm` log's values tell; and a time column's unit.

#include <algorithm>
#include <cctype>
#include <cmath>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/log_reading.hpp"

namespace gearpulse::log_reading {

double stated_speed_to_ms(std::string_view name) noexcept {
  if (holds(name, {"km/h", "kmh", "kph", "km/hr", "kmph"})) return kKmhToMs;  // before mph: "kmph" holds it
  if (holds(name, {"mph", "mi/h"})) return kMphToMs;
  if (holds(name, {"m/s", "mps", "meters/second", "metres/second"})) return 1.0;
  if (holds(name, {"knot"})) return kKnotToMs;
  // kn, kt and kts only as the name's last word: the whole unit, after a bracket or right after "speed"
  // (folded, "speed kt" is "speedkt"), not the end of a longer word.
  if (name.ends_with(')') || name.ends_with(']')) name.remove_suffix(1);
  for (std::string_view unit : {"kts", "kn", "kt"}) {
    if (!name.ends_with(unit)) continue;
    const std::string_view before = name.substr(0, name.size() - unit.size());
    if (before.empty() || !std::isalpha(static_cast<unsigned char>(before.back())) ||
        before.ends_with("speed"))
      return kKnotToMs;
  }
  return 0.0;
}

std::optional<Quantity> quantity_cell(std::string_view cell) noexcept {
  // The names pint gives the units of the readings these readers take (python-OBD's Unit), and plurals.
  static constexpr std::pair<std::string_view, std::string_view> kUnits[] = {
      {"revolutions_per_minute", "rpm"},
      {"kilometer_per_hour", "km/h"},
      {"kilometers_per_hour", "km/h"},
      {"mile_per_hour", "mph"},
      {"miles_per_hour", "mph"},
      {"meter_per_second", "m/s"},
      {"meters_per_second", "m/s"},
      {"knot", "knots"},
      {"knots", "knots"}};
  cell = trim(cell);
  const std::size_t space = cell.rfind(' ');
  if (space == std::string_view::npos) return std::nullopt;
  const std::string_view number = trim(cell.substr(0, space)), unit = cell.substr(space + 1);
  if (number.empty()) return std::nullopt;
  for (const auto& [pint, ours] : kUnits)
    if (unit == pint) return Quantity{number, ours};
  return std::nullopt;
}

std::string_view number_in_unit(std::string_view cell, std::string_view unit) noexcept {
  const std::optional<Quantity> q = quantity_cell(cell);
  return q && q->unit == unit ? q->number : cell;
}

SpeedUnit unit_told_by_values(std::span<const double> speeds) {
  constexpr std::size_t kMinValues = 10;
  // Off a whole km/h by the printed digits (two decimals are 0.008 km/h in mph, 0.018 in m/s) and, in mph,
  // by the conversion factors loggers use (1 / 1.609344, 1 / 1.609, 0.6214, 0.62137: up to 0.02 % apart);
  // m/s is km/h divided by exactly 3.6.
  constexpr double kDigits = 0.02, kMphFactor = 3e-4;
  std::vector<double> moving;
  for (const double v : speeds)
    if (std::isfinite(v) && v > 0.0) moving.push_back(v);
  std::sort(moving.begin(), moving.end());
  moving.erase(std::unique(moving.begin(), moving.end()), moving.end());
  const bool fractions =
      std::any_of(moving.begin(), moving.end(), [](double v) { return std::abs(v - std::round(v)) > 1e-6; });
  if (moving.size() >= kMinValues && fractions)
    for (const SpeedUnit& unit : {kMph, kMetresPerSecond}) {
      const double step = kKmhToMs / unit.to_ms;  // 1 km/h in the unit
      const double factor = unit.to_ms == kMph.to_ms ? kMphFactor : 0.0;
      const bool whole = std::all_of(moving.begin(), moving.end(), [&](double v) {
        const double kmh = v / step;
        return std::abs(kmh - std::round(kmh)) <= kDigits + factor * kmh;
      });
      if (whole) return unit;
    }
  return kKmh;
}

double time_unit(std::string_view folded_name) {
  std::string base(folded_name.substr(0, folded_name.find_first_of("([")));
  bool ms = folded_name.substr(base.size()) == "(ms)" || folded_name.substr(base.size()) == "[ms]";
  if (!ms && base.size() > 2 && base.ends_with("ms")) {
    base.resize(base.size() - 2);
    ms = true;
  }
  if (base == "time" || base == "timestamp" || base == "seconds" || base == "t" || base == "ts")
    return ms ? 1e-3 : 1.0;
  return 0.0;
}

}  // namespace gearpulse::log_reading
